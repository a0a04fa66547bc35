"""Speed against accuracy for a few model settings, on the fitting split only.

``python -m torch_depth_sr.evaluation.tradeoffs [--configs JSON ...] [--part accuracy|timing|both]``

* accuracy: mean RMSE of tracks ``paper`` and ``sensor`` over the full images of the eleven Middlebury
  2006 scenes (the split the defaults were fitted on; the other scenes are for reporting);
* timing: median seconds of the model on a 640×480 synthetic frame (σ = 5, 5 % holes), after a warm-up,
  with the threads torch has.

Each config is a JSON dict of :class:`~torch_depth_sr.RestorerConfig` overrides; ``{}`` is the default.
"""
from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np
import torch

from ..model import DepthRestorer

DEFAULT_CONFIGS = (
    {},
    {"search_window": 11, "match_layers": [2]},  # the "fast" preset
    {"search_window": 11, "match_layers": [2], "k": 6},
    {"search_window": 11, "match_layers": [2], "num_layers": 5},
    {"search_window": 7, "match_layers": [2]},
    {"match_layers": []},
    {"block_size": 5},
)


def _model(overrides: dict) -> DepthRestorer:
    d = dict(overrides)
    if "match_layers" in d:
        d["match_layers"] = tuple(d["match_layers"])
    return DepthRestorer(**d)


def fitting_samples(tracks=("paper", "sensor")):
    """Degraded full-size 2006 scenes, one dict per (track, scene)."""
    from .._data_root import data_root
    from ..datasets.discover import find_scenes
    from .protocols import make_degradation

    loaded = [r.load() for r in find_scenes(data_root(), "paper") if r.year == 2006]
    if not loaded:
        raise FileNotFoundError("no Middlebury 2006 scenes under the data root (set TORCH_DEPTH_SR_DATA).")
    out = []
    for track in tracks:
        deg = make_degradation(track)
        for s in loaded:
            d = deg(s)
            out.append({"track": track, "name": s["name"], "depth": d["depth"][None], "rgb": d["rgb"][None],
                        "gt": d["gt"][None], "mask": d["mask"][None]})
    return out


def accuracy(overrides: dict, samples) -> dict:
    """Mean RMSE over GT-known pixels, per track."""
    model = _model(overrides)
    per_track: dict = {}
    with torch.no_grad():
        for s in samples:
            p = model(s["depth"], s["rgb"])
            e = float((((p - s["gt"]) ** 2 * s["mask"]).sum() / s["mask"].sum()) ** 0.5)
            per_track.setdefault(s["track"], []).append(e)
    return {t: float(np.mean(v)) for t, v in per_track.items()}


def timing(overrides: dict, height: int = 480, width: int = 640, repeats: int = 3) -> float:
    """Median seconds of one restoration of a synthetic frame, after a warm-up."""
    from .speed import make_inputs

    y, rgb, _ = make_inputs(height, width, 1)
    model = _model(overrides)
    times = []
    with torch.no_grad():
        model(y, rgb)
        for _ in range(repeats):
            t0 = time.perf_counter()
            model(y, rgb)
            times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--configs", nargs="*", default=None, help="JSON dicts of RestorerConfig overrides")
    p.add_argument("--part", choices=["accuracy", "timing", "both"], default="both")
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args(argv)
    configs = [json.loads(c) for c in args.configs] if args.configs else [dict(c) for c in DEFAULT_CONFIGS]
    samples = fitting_samples() if args.part != "timing" else None
    print(f"threads={torch.get_num_threads()}; RMSE: 2006 scenes, full images; seconds: 640x480 synthetic")
    for c in configs:
        cells = []
        if samples is not None:
            cells += [f"{t} {v:.4f}" for t, v in accuracy(c, samples).items()]
        if args.part != "accuracy":
            cells.append(f"{timing(c, repeats=args.repeats):.3f} s")
        print(f"{json.dumps(c, sort_keys=True):65s} " + "  ".join(cells), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
