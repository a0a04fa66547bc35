"""Documented parameter search on the fitting split only (Middlebury 2006 + synthetic scenes).

``python -m torch_depth_sr.evaluation.tune [--rounds 2] [--crop 160]`` runs a coordinate search:
each parameter in turn is multiplied by a few factors, the best mean RMSE over tracks ``paper``
and ``sensor`` on centre crops of the 2006 scenes (plus synthetic scenes) is kept, and the
rounds repeat with finer factors. It prints every trial and the final values as JSON (a dict that ``--start``
takes back). The 2005, 2003 and 2001 scenes are never used here.

Parameters are named by their dotted version-2 paths (``weights.lam``, ``block_matching.temperature``; see
``docs/config.md``); version-1 flat names (``lam``, ``temperature``) work too, read from and written through the
version-1 view of the config (:func:`~torch_depth_sr.config.apply_overrides`).
"""
from __future__ import annotations

import argparse
import json
import time
from typing import Any, Callable, Iterable, Optional, Sequence

import torch

from ..config import RestorerConfig, apply_overrides
from ..config.version1 import FLAT_FIELDS, to_version1
from ..model import DepthRestorer

__all__ = ["SEARCH", "fitting_samples", "errors_by", "score", "coordinate_search", "get_value", "main"]

SEARCH = ("singular.sigma_floor", "guided_prior.weight", "weights.lam", "weights.eta", "weights.mu2", "weights.mu1",
          "weights.gamma", "block_matching.color_weight", "block_matching.temperature")


def get_value(config: RestorerConfig, name: str) -> Any:
    """The setting ``name`` of ``config``: a dotted version-2 path (``"weights.lam"``; None where a group on the
    path is off) or a version-1 flat name (``"lam"``)."""
    if name in FLAT_FIELDS:  # guided_prior: the version-1 weight β (0 = off)
        return to_version1(config)[name]
    value = config
    for part in name.split("."):
        if value is None:
            return None
        if not hasattr(value, part):
            raise ValueError(f"unknown setting {name!r}: use a dotted path such as 'weights.lam' (docs/config.md) "
                             "or a version-1 flat name such as 'lam'.")
        value = getattr(value, part)
    return value


def fitting_samples(crop: Optional[int], n_synthetic: int = 4, tracks: Sequence[str] = ("paper", "sensor")
                    ) -> list[dict]:
    """Degraded 2006 scenes (+ ``n_synthetic`` synthetic ones), one dict per (track, scene); centre
    ``crop``×``crop`` crops, or the full images when ``crop`` is None."""
    from .._data_root import data_root
    from ..datasets.discover import find_scenes
    from ..datasets.synthetic import make_scene
    from ..degradations import make_degradation

    out = []
    scenes = [r for r in find_scenes(data_root(), "paper") if r.year == 2006]
    loaded = [r.load() for r in scenes]
    if not loaded and not n_synthetic:
        raise FileNotFoundError("no Middlebury 2006 scenes under the data root (set TORCH_DEPTH_SR_DATA).")
    for i in range(n_synthetic):
        s = make_scene(crop or 160, crop or 160, seed=1000 + i)
        loaded.append({**s, "name": f"synthetic{i}"})
    for track in tracks:
        deg = make_degradation(track)
        for s in loaded:
            d = deg(s)
            sl = (Ellipsis,)
            if crop is not None:
                h, w = d["gt"].shape[-2:]
                t, l = max(0, (h - crop) // 2), max(0, (w - crop) // 2)
                sl = (Ellipsis, slice(t, t + crop), slice(l, l + crop))
            out.append({"track": track, "name": s["name"], "depth": d["depth"][sl][None], "rgb": d["rgb"][sl][None],
                        "gt": d["gt"][sl][None], "mask": d["mask"][sl][None]})
    return out


def errors_by(model: DepthRestorer, samples: Iterable[dict], key: str, metric: str = "rmse") -> dict:
    """``{sample[key]: [error per sample]}``: RMSE or MAE over ``mask`` of ``model`` on each sample
    (guided upsampling where a sample has a ``factor``)."""
    out: dict = {}
    with torch.no_grad():
        for s in samples:
            p = model(s["depth"], s["rgb"], scale_factor=s.get("factor"))
            diff = (p - s["gt"]).abs() if metric == "mae" else (p - s["gt"]) ** 2
            e = float((diff * s["mask"]).sum() / s["mask"].sum())
            out.setdefault(s[key], []).append(e if metric == "mae" else e ** 0.5)
    return out


def score(config: RestorerConfig, samples: Iterable[dict]) -> float:
    """Mean RMSE over all samples."""
    errs = [e for v in errors_by(DepthRestorer(config), samples, "track").values() for e in v]
    return sum(errs) / len(errs)


def coordinate_search(config: RestorerConfig, samples: Sequence[dict], rounds: int = 2, names: Sequence[str] = SEARCH,
                      log: Callable[[str], object] = print, factors_first: Sequence[float] = (0.25, 0.5, 2.0, 4.0)
                      ) -> tuple[RestorerConfig, float]:
    best = score(config, samples)
    log(f"start {best:.4f}")
    for rnd in range(rounds):
        factors = factors_first if rnd == 0 else (0.7, 1.4)
        for name in names:
            base = get_value(config, name)
            if base is None:  # a step that is off
                log(f"  skip {name}: off in this config")
                continue
            for f in factors:
                trial = apply_overrides(config, {name: base * f})
                t0 = time.perf_counter()
                s = score(trial, samples)
                log(f"round {rnd} {name}={get_value(trial, name):.4g}: {s:.4f} ({time.perf_counter() - t0:.1f}s)")
                if s < best:
                    best, config = s, trial
            log(f"  keep {name}={get_value(config, name):.4g} -> {best:.4f}")
    return config, best


def main(argv: Optional[Sequence[str]] = None) -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--crop", type=int, default=160)
    p.add_argument("--names", nargs="*", default=list(SEARCH),
                   help="settings to search: dotted paths (weights.lam) or version-1 names (lam)")
    p.add_argument("--start", default=None,
                   help='JSON of RestorerConfig overrides to start from (docs/config.md), e.g. '
                        '\'{"weights.lam": 0.8}\', \'{"weights": {"lam": 0.8}}\' or the version-1 \'{"lam": 0.8}\'')
    p.add_argument("--factors", nargs="*", type=float, default=[0.25, 0.5, 2.0, 4.0])
    args = p.parse_args(argv)
    torch.set_num_threads(max(1, torch.get_num_threads()))
    samples = fitting_samples(args.crop)
    cfg = apply_overrides(RestorerConfig(), json.loads(args.start) if args.start else {})
    for name in args.names:  # refuse a mistyped name before the first run
        get_value(cfg, name)
    cfg, best = coordinate_search(cfg, samples, args.rounds, args.names, factors_first=tuple(args.factors))
    print(json.dumps({n: get_value(cfg, n) for n in args.names}, indent=1), f"score {best:.4f}")


if __name__ == "__main__":
    main()
