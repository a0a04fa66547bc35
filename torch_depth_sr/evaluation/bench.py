"""``torch-depth-sr bench``: the protocols of ``shared/docs/benchmark.md`` on the data under ``--data``."""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from ..errors import UsageError
from ..fill import fill_holes
from .methods import DENOISE_METHODS, UPSAMPLE_METHODS, run_method

__all__ = ["FACTORS", "run_bench", "summarise"]

FACTORS = (2, 4, 8, 16)


def _samples(track: str, root, scenes, sigma):
    """Yield degraded samples of a track (one per scene, or per scene and factor)."""
    from ..datasets.discover import find_scenes
    from ..degradations import make_degradation

    records = find_scenes(root, track)
    if scenes:
        wanted = {s.lower() for s in scenes}
        records = [r for r in records if r.name.lower() in wanted]
    if not records:
        raise UsageError(f"no scenes of track {track!r} under {root} (scenes filter: {scenes}); check --data and "
                         "--scenes")
    if track in ("paper", "sensor"):
        kw = {} if sigma is None else {"sigma": sigma}
        degrade = make_degradation(track, **kw)
        for r in records:
            sample = degrade(r.load())
            # noise can push tiny disparities below 0; a sensor reports no negative values, so those become
            # "no measurement" (0) for every method alike
            sample["depth"] = sample["depth"].clamp_min(0)
            yield r, sample
    elif track in ("upsample-a", "upsample-b"):
        for r in records:
            for f in FACTORS:
                yield r, r.load(factor=f)
    else:
        for r in records:
            yield r, r.load()


def _metrics(pred: torch.Tensor, sample: dict, track: str) -> dict:
    from ..metrics import evaluate

    if track in ("upsample-a", "upsample-b"):
        gt = sample["gt"][None].to(pred)
        err = (pred - gt).double()
        # also as an 8-bit PNG stores the output: the ground truth is whole grey levels, and the published figures
        # of this benchmark were computed from the authors' 8-bit PNG results
        err_8bit = (pred.clamp(0, 255).round() - gt).double()
        return {"rmse": float(err.pow(2).mean().sqrt()), "mae": float(err.abs().mean()),
                "rmse_8bit": float(err_8bit.pow(2).mean().sqrt()), "mae_8bit": float(err_8bit.abs().mean())}
    if track == "real":
        y = sample["depth"]
        return {"holes_in": float((y <= 0).float().mean()), "holes_out": float((pred <= 0).float().mean())}
    return {k: (float(v) if v is not None else None) for k, v in evaluate(pred, sample).items()}


def _parse_config(text):
    """``--config`` JSON of RestorerConfig overrides, checked before any scene runs: the version-2 form
    (``{"block_matching": {"k": 10}}``, dotted ``{"block_matching.k": 10}``) or version-1 flat names (``{"k": 10}``),
    as :func:`~torch_depth_sr.config.apply_overrides` takes them."""
    if not text:
        return None
    from ..config import RestorerConfig, apply_overrides

    try:
        overrides = json.loads(text)
    except json.JSONDecodeError as e:
        raise UsageError(f"--config must be a JSON object of RestorerConfig overrides; got {text!r} ({e}).") from e
    if not isinstance(overrides, dict):
        raise UsageError(f"--config must be a JSON object of RestorerConfig overrides; got {text!r}.")
    try:
        apply_overrides(RestorerConfig(), overrides)
    except (TypeError, ValueError) as e:
        raise UsageError(f"--config: {e}") from e
    return overrides


def _parse_pretrained(folder):
    """``--pretrained FOLDER`` for the ``trained`` methods, checked before any scene runs (None = the shipped)."""
    if folder is None:
        return None
    from ..errors import UsageError

    if not (Path(folder) / "config.json").is_file() or not (Path(folder) / "state_dict.pt").is_file():
        raise UsageError(f"--pretrained {folder!r}: not a saved model folder (config.json and state_dict.pt, as "
                         "DepthRestorer.save writes them, e.g. a training run's best/).")
    return str(folder)


def run_bench(args: argparse.Namespace) -> int:
    from .._data_root import data_root
    from .report import metadata as _metadata, print_table as _print_table

    if args.track == "speed":
        from .speed import run_speed

        return run_speed(args)
    if args.track == "stream":
        from .stream import run_stream_track

        return run_stream_track(args)
    if args.track == "gdsr":
        from .gdsr import run_gdsr

        return run_gdsr(args, config=_parse_config(getattr(args, "config", None)))
    root = Path(args.data) if args.data else data_root()
    upsampling = args.track in ("upsample-a", "upsample-b")
    methods = args.methods or list(UPSAMPLE_METHODS if upsampling else DENOISE_METHODS)
    if args.track == "real":
        methods = args.methods or ["input", "jbf", "full"]
    config = _parse_config(getattr(args, "config", None))
    pretrained = _parse_pretrained(getattr(args, "pretrained", None))
    results = []
    items = list(_samples(args.track, root, args.scenes, args.sigma))
    bar = tqdm(total=len(items) * len(methods), desc=f"bench {args.track}", unit="run")
    for rec, sample in items:
        preds = {}
        for m in methods:
            t0 = time.perf_counter()
            pred = run_method(m, sample, args.device, config, track=args.track, pretrained=pretrained).cpu()
            secs = time.perf_counter() - t0
            preds[m] = pred
            row = {"track": args.track, "scene": rec.name, "dataset": rec.dataset, "method": m,
                   "scale": float(sample.get("factor") or sample.get("scale") or 1), "seconds": secs}
            row.update(_metrics(pred, sample, args.track))
            results.append(row)
            bar.update(1)
        _save_extras(args, rec, sample, preds)
    bar.close()
    summary = summarise(results, args.track)
    cols = ["method"] + (["scale"] if upsampling else []) + [c for c in ("rmse", "mae", "rmse_8bit", "mae_8bit",
                                                                          "bad", "rmse_holes",
                                                                          "rmse_edges", "flying_left", "holes_in", "holes_out",
                                                                          "wins_vs_jbf", "seconds") if
                                                               any(c in r for r in summary)]
    title = f"track {args.track}: mean over {len({r['scene'] for r in results})} scene(s)"
    if args.sigma is not None:
        title += f", sigma={args.sigma}"
    _print_table(summary, cols, title)
    if getattr(args, "per_scene", False):
        _print_table(results, ["scene", "method", "scale"] + cols[1 + upsampling:-1] + ["seconds"], "per scene")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        meta = _metadata(args.device)
        meta.update(track=args.track, sigma=args.sigma, data=str(root), config_overrides=config or {},
                    pretrained=pretrained)
        Path(args.json).write_text(json.dumps({"metadata": meta, "summary": summary, "results": results}, indent=1))
        print(f"json: {args.json}")
    return 0


def summarise(results: list[dict], track: str) -> list[dict]:
    """Mean per method (and per scale for upsampling); geometric-mean RMSE for upsample-a; wins vs jbf."""
    keys = sorted({(r["method"], r["scale"] if track.startswith("upsample") else 0) for r in results},
                  key=lambda k: (k[1], [r["method"] for r in results].index(k[0])))
    out = []
    for m, s in keys:
        rows = [r for r in results if r["method"] == m and (not track.startswith("upsample") or r["scale"] == s)]
        agg = {"method": m}
        if track.startswith("upsample"):
            agg["scale"] = int(s)
        for c in ("rmse", "mae", "rmse_8bit", "mae_8bit", "bad", "rmse_holes", "rmse_edges", "flying_left",
                  "holes_in", "holes_out", "seconds"):
            vals = [r[c] for r in rows if r.get(c) is not None and not (isinstance(r[c], float) and math.isnan(r[c]))]
            if vals:
                agg[c] = float(np.mean(vals))
        jbf = {r["scene"] + str(r["scale"]): r["rmse"] for r in results if r["method"] == "jbf" and "rmse" in r}
        if jbf and m != "jbf" and "rmse" in agg:
            wins = [r["rmse"] < jbf[r["scene"] + str(r["scale"])] for r in rows if r["scene"] + str(r["scale"]) in jbf]
            agg["wins_vs_jbf"] = f"{sum(wins)}/{len(wins)}"
        out.append(agg)
    if track == "upsample-a":
        for m in dict.fromkeys(r["method"] for r in results):
            vals = [r["rmse"] for r in results if r["method"] == m]
            out.append({"method": m, "scale": "geo", "rmse": float(np.exp(np.mean(np.log(vals))))})
    return out


def _save_extras(args, rec, sample: dict, preds: dict) -> None:
    name = f"{rec.dataset}_{rec.name}" + (f"_x{sample['factor']}" if sample.get("factor") else "")
    if getattr(args, "save_inputs", None):
        d = Path(args.save_inputs)
        d.mkdir(parents=True, exist_ok=True)
        np.save(d / f"{name}_input.npy", sample["depth"][0].numpy())
        if "gt" in sample:
            np.save(d / f"{name}_gt.npy", sample["gt"][0].numpy())
            np.save(d / f"{name}_mask.npy", sample["mask"][0].numpy())
    if getattr(args, "figures", None):
        from ..figures import comparison_figure

        has_gt = "gt" in sample
        # without ground truth (track real) the reference panel is the input with holes filled (push-pull)
        gt = sample["gt"] if has_gt else fill_holes(sample["depth"][None], (sample["depth"][None] > 0).float())[0]
        valid = sample["mask"] if has_gt else torch.ones_like(gt)
        deg = sample["depth"]
        if deg.shape[-2:] != gt.shape[-2:]:
            deg = torch.nn.functional.interpolate(deg[None], size=gt.shape[-2:], mode="nearest")[0]
        comparison_figure(Path(args.figures) / f"{args.track}_{name}.png", sample["rgb"], deg, gt, valid,
                          {k: v for k, v in preds.items() if k != "input"}, ref_name="gt" if has_gt else "filled")
