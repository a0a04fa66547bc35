"""Documented parameter search on the fitting split only (Middlebury 2006 + synthetic scenes).

``python -m torch_depth_sr.evaluation.tune [--rounds 2] [--crop 160]`` runs a coordinate search:
each parameter in turn is multiplied by a few factors, the best mean RMSE over tracks ``paper``
and ``sensor`` on centre crops of the 2006 scenes (plus synthetic scenes) is kept, and the
rounds repeat with finer factors. It prints every trial and the final config as JSON. The
2005, 2003 and 2001 scenes are never used here.
"""
from __future__ import annotations

import argparse
import json
import time
from typing import Callable, Iterable, Optional, Sequence

import torch

from ..config import RestorerConfig
from ..model import DepthRestorer

__all__ = ["SEARCH", "fitting_samples", "errors_by", "score", "coordinate_search", "main"]

SEARCH = ("singular_sigma_floor", "guided_prior", "lam", "eta", "mu2", "mu1", "gamma", "color_weight", "temperature")


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
            base = getattr(config, name)
            for f in factors:
                trial = config.replace(**{name: base * f})
                t0 = time.perf_counter()
                s = score(trial, samples)
                log(f"round {rnd} {name}={getattr(trial, name):.4g}: {s:.4f} ({time.perf_counter() - t0:.1f}s)")
                if s < best:
                    best, config = s, trial
            log(f"  keep {name}={getattr(config, name):.4g} -> {best:.4f}")
    return config, best


def main(argv: Optional[Sequence[str]] = None) -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--crop", type=int, default=160)
    p.add_argument("--names", nargs="*", default=list(SEARCH))
    p.add_argument("--start", default=None, help="JSON of config overrides to start from")
    p.add_argument("--factors", nargs="*", type=float, default=[0.25, 0.5, 2.0, 4.0])
    args = p.parse_args(argv)
    torch.set_num_threads(max(1, torch.get_num_threads()))
    samples = fitting_samples(args.crop)
    cfg = RestorerConfig().replace(**(json.loads(args.start) if args.start else {}))
    cfg, best = coordinate_search(cfg, samples, args.rounds, args.names, factors_first=tuple(args.factors))
    print(json.dumps({n: getattr(cfg, n) for n in args.names}, indent=1), f"score {best:.4f}")


if __name__ == "__main__":
    main()
