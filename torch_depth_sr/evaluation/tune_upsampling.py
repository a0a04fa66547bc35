"""Fit the guided-upsampling multipliers (``RestorerConfig.upsampling.multipliers``) on the fitting split only.

Fitting set: the eleven Middlebury 2006 scenes at full stored size; the ground truth with its unknown
pixels filled by push-pull is area-downsampled by s = 2 and 4 (the degradation of the upsampling sets,
whose inputs match area averaging of their ground truth best), σ = 5 Gaussian noise is added (seeded)
and the result is rounded to 8 bits. Score: MAE over GT-known pixels, mean over scenes, per factor.
The upsampling sets themselves are never used here.

``python -m torch_depth_sr.evaluation.tune_upsampling [--trials JSON ...]`` prints one row per trial
(each a JSON dict of ``RestorerConfig`` overrides as :func:`~torch_depth_sr.config.apply_overrides` takes them;
the default trials are the ones the shipped multipliers were chosen from, each trial's multipliers in full: the
ones it leaves out are 1, as in the version-1 ``upsample_scale`` they were written in).
"""
from __future__ import annotations

import argparse
import json
import time
from typing import Iterable, Optional, Sequence

import numpy as np
import torch
import torch.nn.functional as F

from ..config import RestorerConfig, apply_overrides
from ..model import DepthRestorer
from .tune import errors_by

__all__ = ["DEFAULT_TRIALS", "upsampling_fitting_samples", "score", "main"]

DEFAULT_TRIALS = tuple({"upsampling.multipliers": dict(lam=1.0, eta=1.0, gamma=1.0, mu1=mu1, mu2=mu2)}
                       for mu1, mu2 in ((1.0, 1.0), (3.0, 1.0), (6.0, 1.0), (12.0, 1.0), (3.0, 2.0), (3.0, 3.0),
                                        (4.0, 3.0), (3.0, 5.0)))


def upsampling_fitting_samples(factors: Sequence[int] = (2, 4), sigma: float = 5.0) -> list[dict]:
    from .._data_root import data_root
    from ..datasets.discover import find_scenes
    from ..fill import fill_holes

    out = []
    for ref in find_scenes(data_root(), "paper"):
        if ref.year != 2006:
            continue
        s = ref.load()
        gt, mask, rgb = s["gt"][None].float(), s["mask"][None].float(), s["rgb"][None].float()
        h, w = gt.shape[-2:]
        complete = fill_holes(gt, mask)
        for f in factors:
            hh, ww = h // f * f, w // f * f
            rng = np.random.default_rng([f, len(out)])
            lr = F.avg_pool2d(complete[..., :hh, :ww], f)
            lr = (lr + sigma * torch.from_numpy(rng.standard_normal(lr.shape)).float()).round().clamp(0, 255)
            out.append(dict(name=s["name"], factor=f, depth=lr, rgb=rgb[..., :hh, :ww], gt=gt[..., :hh, :ww],
                            mask=mask[..., :hh, :ww]))
    if not out:
        raise FileNotFoundError("no Middlebury 2006 scenes under the data root (set TORCH_DEPTH_SR_DATA).")
    return out


def score(config: RestorerConfig, samples: Iterable[dict]) -> dict:
    """Mean MAE per factor."""
    per_factor = errors_by(DepthRestorer(config), samples, "factor", metric="mae")
    return {f: float(np.mean(v)) for f, v in sorted(per_factor.items())}


def main(argv: Optional[Sequence[str]] = None) -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--trials", nargs="*", default=None,
                   help='JSON dicts of RestorerConfig overrides (docs/config.md), e.g. '
                        '\'{"upsampling.multipliers": {"mu1": 6.0}}\' or the version-1 '
                        '\'{"upsample_scale": {"mu1": 6.0}}\'')
    args = p.parse_args(argv)
    trials = [json.loads(t) for t in args.trials] if args.trials else list(DEFAULT_TRIALS)
    configs = [apply_overrides(RestorerConfig(), t) for t in trials]  # refuse a mistyped name before the first run
    samples = upsampling_fitting_samples()
    print(f"{len(samples)} samples (2006 scenes x factors 2, 4); MAE per factor")
    for t, config in zip(trials, configs):
        t0 = time.perf_counter()
        res = score(config, samples)
        cells = "  ".join(f"x{f}: {v:.4f}" for f, v in res.items())
        print(f"{json.dumps(t, sort_keys=True):60s} {cells}  ({time.perf_counter() - t0:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
