"""examples/stream_video.py runs as a user would run it: a short synthetic video, the scores and the picture."""
import importlib.util
from pathlib import Path

import cv2


def test_stream_video_example_scores_the_stream_and_writes_its_picture(tmp_path):
    path = Path(__file__).resolve().parents[1] / "examples" / "stream_video.py"
    spec = importlib.util.spec_from_file_location("stream_video", path)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    png = tmp_path / "video.png"
    scores = example.main("static-2movers", frames=8, png=str(png))
    frame, stream = scores["frame by frame"], scores["stream"]
    assert stream["flicker"] < frame["flicker"] and stream["rmse"] < frame["rmse"]
    img = cv2.imread(str(png))
    assert img is not None and img.shape == (2 * 2 * 120, 2 * 3 * 160, 3)
