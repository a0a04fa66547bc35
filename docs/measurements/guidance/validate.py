"""The training command's validation figure for saved or shipped models, optionally with config overrides.

    PYTHONPATH=. python docs/measurements/guidance/validate.py denoise-guided \
        'denoise-guided:{"guidance": {"range": 16}}' runs/g2-r16/best

Each argument is ``MODEL[:JSON]``: a shipped name (``from_pretrained``) or a saved folder (a ``/`` in it), and
settings to change in its config (its weights are kept), as ``config.apply_overrides`` takes them: version-2
groups or dotted paths, or version-1 flat names (``{"guidance_range": 16}``). Prints the mean RMSE over the two
tracks and per track RMSE / MAE: the same 16 crops per track, σ = 5, as ``torch-depth-sr train`` with its defaults
(``--val-size 16``), so the figure equals a run's step-0 line with ``--init MODEL``.
"""
from __future__ import annotations

import json
import sys
import time
from typing import Optional, Sequence

import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.config import apply_overrides
from torch_depth_sr.training import TrainConfig, evaluate, make_datasets


def main(argv: Optional[Sequence[str]] = None) -> None:
    torch.set_num_threads(1)
    cfg = TrainConfig(out="unused", val_size=16)
    _, val_sets = make_datasets(cfg.data, crop=cfg.crop, train_length=4, val_length=cfg.val_size,
                                val_scenes=cfg.val_scenes, synthetic=cfg.synthetic, sigma=cfg.sigma,
                                val_sigma=cfg.val_sigma, scale_factor=cfg.scale_factor, degradation=cfg.degradation,
                                seed=cfg.seed, use_middlebury=cfg.use_middlebury)
    for arg in (sys.argv[1:] if argv is None else argv):
        name, _, overrides = arg.partition(":")
        base = DepthRestorer.load(name) if "/" in name else DepthRestorer.from_pretrained(name)
        model = DepthRestorer(apply_overrides(base.config, json.loads(overrides) if overrides else {}))
        model.load_state_dict(base.state_dict())
        model.eval()
        t = time.perf_counter()
        res = {k: evaluate(model, ds) for k, ds in val_sets.items()}
        mean = sum(v["rmse"] for v in res.values()) / len(res)
        per = "  ".join(f"{k} {v['rmse']:.4f} / {v['mae']:.4f}" for k, v in res.items())
        print(f"{arg}  rmse={mean:.4f}  ({per})  {time.perf_counter() - t:.0f} s", flush=True)


if __name__ == "__main__":
    main()
