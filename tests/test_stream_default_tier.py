"""The ``default`` tier in a stream (issue 28, thirty-third stop): its ``config.json`` runs one layer on the whole
frame once a stream has a past, with a temporal prior of half the stream model's weight. With all eight layers
everywhere and that weight, its stream was worse than frame-by-frame restoration on textured Middlebury 2006 streams
(``docs/measurements/issue28-stream/thirty-third-stop/``)."""
from __future__ import annotations

import pytest
import torch

from torch_depth_sr import DepthRestorer, StreamRestorer, restore_depth
from torch_depth_sr._data_root import require_data_root
from torch_depth_sr.datasets.discover import find_scenes
from torch_depth_sr.degradations import make_degradation


def test_the_default_tier_streams_with_its_fitted_settings():
    model = DepthRestorer.from_preset("default")
    assert model.config.stream is not None
    settings = StreamRestorer(model).settings
    assert (settings.layers, settings.weight) == (1, 0.25)


def test_a_default_tier_stream_of_a_textured_2006_scene_beats_frame_by_frame():
    """Wood1 (fitting split), a 128×160 centre crop, the ``paper`` degradation with seed t in frame t: over frames
    8–11 the stream's RMSE is below frame-by-frame's, and below the stream's with every layer everywhere and the
    weight of before (which came out above frame-by-frame's here: 0.85 against 0.61)."""
    torch.set_num_threads(1)
    root = require_data_root("middlebury2006")
    rec = next((r for r in find_scenes(root, "paper") if r.name == "Wood1"), None)
    if rec is None:
        pytest.skip("Wood1 is not under the data root")
    scene = rec.load()
    h, w = scene["gt"].shape[-2:]
    rows, cols = slice(h // 2 - 64, h // 2 + 64), slice(w // 2 - 80, w // 2 + 80)
    scene = {k: v[..., rows, cols].clone() if torch.is_tensor(v) and v.shape[-2:] == (h, w) else v
             for k, v in scene.items()}
    model = DepthRestorer.from_preset("default")
    streams = {"fitted": StreamRestorer(model),
               "every layer": StreamRestorer(model, {"layers": None, "weight": 0.5})}  # as it streamed before
    errors: dict = {"frame": [], "fitted": [], "every layer": []}
    with torch.no_grad():
        for t in range(12):
            d = make_degradation("paper", seed=t)(dict(scene))
            depth, rgb = d["depth"].clamp_min(0)[None], d["rgb"][None]
            outs = {k: s.step(depth, rgb) for k, s in streams.items()}
            if t < 8:
                continue
            outs["frame"] = restore_depth(depth, rgb, model=model)
            for k, out in outs.items():
                errors[k].append(float((out - d["gt"]).pow(2).mean().sqrt()))
    rmse = {k: sum(v) / len(v) for k, v in errors.items()}
    assert rmse["fitted"] < rmse["frame"], rmse
    assert rmse["fitted"] < rmse["every layer"], rmse
