"""Issue 28, twenty-sixth stop: the well-measured pixels of a slow mover that come out far off, with the stream's
rule for its single measurements (``StreamConfig.single_support``) at 1, 2 and 3 agreeing neighbours and off.

The count of ``tests/test_stream_known_limits.py`` (``_far_off``): pixels of ``static-2movers@202`` (26 frames,
120×160) that the sensor measured within 10 mm of the truth and that come out more than 100 mm off, summed over the
frames; the test asks the stream for no more than frame by frame's.

    OMP_NUM_THREADS=2 python docs/measurements/issue28-stream/twenty-sixth-stop/far_off_counts.py
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[4] / "tests"))
from test_stream_known_limits import _far_off  # noqa: E402

print(f"frame by frame: {_far_off(202, 26)[1]}")
for count in (None, 1, 2, 3):
    print(f"single_support {count}: {_far_off(202, 26, {'single_support': count}, frame_by_frame=False)[0]}", flush=True)
