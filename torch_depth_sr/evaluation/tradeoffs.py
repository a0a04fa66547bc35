"""Speed against accuracy for a few model settings, on the fitting split only.

``python -m torch_depth_sr.evaluation.tradeoffs [--configs JSON ...] [--part accuracy|timing|both]``

* accuracy: mean RMSE of tracks ``paper`` and ``sensor`` over the full images of the eleven Middlebury
  2006 scenes (the split the defaults were fitted on; the other scenes are for reporting);
* timing: median seconds of the model on a 640×480 synthetic frame (σ = 5, 5 % holes), after a warm-up,
  with the threads torch has.

Each config is a JSON dict of :class:`~torch_depth_sr.RestorerConfig` overrides as
:func:`~torch_depth_sr.config.apply_overrides` takes them (version-2 groups, dotted paths, or version-1 flat
names); ``{}`` is the default.
"""
from __future__ import annotations

import argparse
import json
import statistics
import time
from typing import Optional, Sequence

import numpy as np
import torch

from ..config import RestorerConfig, apply_overrides
from ..model import DepthRestorer
from .tune import errors_by, fitting_samples

__all__ = ["DEFAULT_CONFIGS", "accuracy", "timing", "main"]

DEFAULT_CONFIGS = (
    {},
    {"block_matching": {"search_window": 11, "match_layers": [2]}},  # the "fast" preset's window and re-matching
    {"block_matching": {"search_window": 11, "match_layers": [2], "k": 6}},
    {"block_matching": {"search_window": 11, "match_layers": [2]}, "num_layers": 5},
    {"block_matching": {"search_window": 7, "match_layers": [2]}},
    {"block_matching": {"match_layers": []}},
    {"block_matching": {"block_size": 5}},
)


def _model(overrides: dict) -> DepthRestorer:
    return DepthRestorer(apply_overrides(RestorerConfig(), overrides))


def accuracy(overrides: dict, samples: Sequence[dict]) -> dict:
    """Mean RMSE over GT-known pixels, per track."""
    return {t: float(np.mean(v)) for t, v in errors_by(_model(overrides), samples, "track").items()}


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


def main(argv: Optional[Sequence[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--configs", nargs="*", default=None,
                   help='JSON dicts of RestorerConfig overrides (docs/config.md), e.g. '
                        '\'{"block_matching": {"k": 10}}\', '
                        '\'{"block_matching.k": 10}\' or the version-1 \'{"k": 10}\'')
    p.add_argument("--part", choices=["accuracy", "timing", "both"], default="both")
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args(argv)
    configs = [json.loads(c) for c in args.configs] if args.configs else [dict(c) for c in DEFAULT_CONFIGS]
    for c in configs:  # refuse a mistyped name before the first run
        apply_overrides(RestorerConfig(), c)
    samples = fitting_samples(None, n_synthetic=0) if args.part != "timing" else None
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
