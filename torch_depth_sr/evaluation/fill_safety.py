"""Do filled holes invent surfaces?  ``python -m torch_depth_sr.evaluation.fill_safety``.

Measures, for the model (``full``, optional ``--config`` overrides as in ``bench``):

(a) **bridging share** on the ``sensor`` track: among the hole pixels of the edge band (pixels the
    degradation set to 0 that lie within 2 px of a depth discontinuity, GT-known), the share whose
    filled value lies *between* the two sides of the edge, more than 3 grey levels from both. The
    two sides are taken from the ground truth: ``lo`` and ``hi`` = the minimum and maximum GT value
    over the pixel's 5×5 neighbourhood of GT-known pixels (the neighbourhood the protocol uses for
    flying pixels). Only pixels on a step count: ``hi − lo > 6`` and the GT itself within 3 grey
    levels of ``lo`` or ``hi`` (on a steep slope the GT lies "between" too; those pixels are left
    out). A pixel is *bridging* when ``lo + 3 < pred < hi − 3``. Also reported: ``edge_off``, the
    share more than 3 grey levels from both sides (bridging plus outside both), and ``wrong_side``,
    the share filled from the other side (within 3 of the side the GT is not on).
(b) **RMSE in holes** (as ``bench --track sensor``: GT-known hole pixels) and overall RMSE, per
    scene and as the mean over the ten held-out 2005/2003/2001 scenes and over the 2006 scenes.
(c) with ``--real``: the share of filled points that are outliers against the share of measured
    points, on the three real frames (TUM, SUN, NYU raw). Each frame is restored in metres,
    back-projected with pinhole intrinsics f = 525 px, c = ((W−1)/2, (H−1)/2) (the TUM/Kinect
    defaults; the NYU raw frame is unregistered and only its depth matters here), and the whole
    cloud (measured + filled points) goes through Open3D's
    ``remove_statistical_outlier(nb_neighbors=20, std_ratio=2.0)``. Needs the optional extra
    ``bench3d`` (``pip install open3d-cpu``); without it (c) is skipped with a message.

``--fill trusted`` runs the model with ``fill="trusted"``: holes left missing count neither as
filled pixels in (a)/(c) nor in the RMSE (the table says how many were left).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
import torch

__all__ = [
    "HELD_OUT",
    "SIDE_TOL",
    "edge_sides",
    "bridging",
    "run_sensor",
    "backproject",
    "outlier_shares",
    "run_real",
    "main",
]

HELD_OUT = ("Art", "Books", "Dolls", "Laundry", "Moebius", "Reindeer", "Cones", "Teddy", "Tsukuba", "Venus")
SIDE_TOL = 3.0  # grey levels


def edge_sides(gt: np.ndarray, known: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi): min and max GT over each pixel's 5×5 neighbourhood of GT-known pixels."""
    import cv2

    k = np.ones((5, 5), np.uint8)
    g = gt.astype(np.float32)
    lo = cv2.erode(np.where(known, g, np.float32(np.inf)), k, borderType=cv2.BORDER_REPLICATE)
    hi = cv2.dilate(np.where(known, g, np.float32(-np.inf)), k, borderType=cv2.BORDER_REPLICATE)
    return lo, hi


def bridging(pred: np.ndarray, sample: dict, tol: float = SIDE_TOL) -> dict:
    """Bridging statistics of the edge-band holes (see the module docstring)."""
    gt = sample["gt"][0].numpy().astype(np.float64)
    known = sample["mask"][0].numpy() > 0.5
    region = known & (sample["holes"][0].numpy() > 0.5) & (sample["edges"][0].numpy() > 0.5)
    lo, hi = edge_sides(gt, known)
    # only pixels on a step: the two sides more than 2·tol apart and the GT itself on one of them
    step = region & (hi - lo > 2 * tol) & ((np.abs(gt - lo) <= tol) | (np.abs(gt - hi) <= tol))
    filled = step & np.isfinite(pred) & (pred > 0)
    p = pred[filled]
    between = (p > lo[filled] + tol) & (p < hi[filled] - tol)
    off = (np.abs(p - lo[filled]) > tol) & (np.abs(p - hi[filled]) > tol)
    wrong = np.abs(p - gt[filled]) > tol  # > tol from its own side (the other side, or in between)
    n = int(filled.sum())
    f = (lambda a: float(a.mean()) if n else math.nan)
    return {"edge_holes": int(region.sum()), "step_holes": int(step.sum()), "edge_filled": n,
            "bridge": f(between), "edge_off": f(off), "wrong_side": f(wrong & ~between & ~off)}


def _model(config: dict, fill: str):
    from ..config import RestorerConfig, apply_overrides
    from ..model import DepthRestorer

    model = DepthRestorer(apply_overrides(RestorerConfig(), config))
    if fill == "all":
        return lambda y, rgb: model(y, rgb)
    return lambda y, rgb: model(y, rgb, fill=fill)


def run_sensor(scenes: Optional[Sequence[str]], config: dict, fill: str, root: Path | str | None = None) -> list[dict]:
    from .._data_root import data_root
    from ..metrics import evaluate
    from .bench import _samples

    run = _model(config, fill)
    rows = []
    for rec, sample in _samples("sensor", root or data_root(), scenes, None):
        with torch.no_grad():
            pred = run(sample["depth"][None], sample["rgb"][None])[0]
        p = pred[0].numpy().astype(np.float64)
        m = evaluate(torch.nan_to_num(pred, nan=0.0), sample)
        holes = (sample["holes"][0].numpy() > 0.5) & (sample["mask"][0].numpy() > 0.5)
        left = holes & ~(np.isfinite(p) & (p > 0))
        if left.any():  # RMSE over the holes that were filled
            s2 = dict(sample, holes=torch.from_numpy((holes & ~left).astype(np.float32))[None])
            m = evaluate(torch.nan_to_num(pred, nan=0.0), s2)
        row = {"scene": rec.name, "year": rec.year, "rmse": m["rmse"], "rmse_holes": m["rmse_holes"],
               "holes_left": float(left.sum() / max(1, holes.sum()))}
        row.update(bridging(p, sample))
        rows.append(row)
        print(f"  {rec.name:10s} rmse {row['rmse']:.3f}  rmse_holes {row['rmse_holes']:.3f}  "
              f"bridge {100 * row['bridge']:.2f}%  off {100 * row['edge_off']:.2f}%  wrong {100 * row['wrong_side']:.2f}% "
              f"(n {row['edge_filled']})  left {100 * row['holes_left']:.1f}%",
              file=sys.stderr, flush=True)
    return rows


def backproject(depth_m: np.ndarray, f: float = 525.0) -> np.ndarray:
    """(H,W) metres → (H·W, 3) points (pinhole, f px, centre at the image centre)."""
    h, w = depth_m.shape
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    z = depth_m.astype(np.float64)
    return np.stack([(u - (w - 1) / 2) * z / f, (v - (h - 1) / 2) * z / f, z], -1).reshape(-1, 3)


def outlier_shares(depth_in: np.ndarray, depth_out: np.ndarray, nb: int = 20, std_ratio: float = 2.0) -> dict:
    """Share of filled and of measured points that Open3D's statistical outlier removal rejects."""
    import open3d as o3d

    measured = (depth_in > 0).reshape(-1)
    valid = (np.isfinite(depth_out) & (depth_out > 0)).reshape(-1)
    filled = valid & ~measured
    keep = valid
    pts = backproject(np.where(np.isfinite(depth_out), depth_out, 0.0))[keep]
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    _, inl = pc.remove_statistical_outlier(nb_neighbors=nb, std_ratio=std_ratio)
    out = np.ones(pts.shape[0], bool)
    out[np.asarray(inl, dtype=np.int64)] = False
    is_filled = filled[keep]
    holes = int((~measured).sum())
    return {"filled_points": int(is_filled.sum()), "holes_left": float(1 - is_filled.sum() / max(1, holes)),
            "outliers_filled": float(out[is_filled].mean()) if is_filled.any() else math.nan,
            "outliers_measured": float(out[~is_filled].mean())}


def run_real(config: dict, fill: str, root: Path | str | None = None) -> list[dict]:
    from .._data_root import data_root
    from ..datasets.real_sensor import DATASET, FRAMES, load_real_frame

    try:
        import open3d  # noqa: F401
    except ImportError as e:
        print(f"(c) skipped: open3d cannot be imported ({e}); install the optional extra "
              "(pip install 'torch-depth-sr[bench3d]', i.e. open3d-cpu; it needs libusb-1.0 on Linux)")
        return []
    run = _model(config, fill)
    base = Path(root or data_root()) / DATASET
    rows = []
    for name in FRAMES:
        d = base / name
        if not d.is_dir():
            print(f"(c) {name}: folder {d} missing, skipped")
            continue
        s = load_real_frame(d, name)
        with torch.no_grad():
            out = run(s["depth"][None], s["rgb"][None])[0, 0].numpy()
        r = {"frame": name}
        r.update(outlier_shares(s["depth"][0].numpy(), out))
        rows.append(r)
        print(f"  {name:8s} filled {r['filled_points']}  outliers filled {100 * r['outliers_filled']:.2f}%  "
              f"measured {100 * r['outliers_measured']:.2f}%", file=sys.stderr, flush=True)
    return rows


def _mean(rows, key, pick):
    vals = [r[key] for r in rows if pick(r) and r[key] is not None and not math.isnan(r[key])]
    return float(np.mean(vals)) if vals else math.nan


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", nargs="*", default=None, help="sensor scenes (default: all 21)")
    ap.add_argument("--config", default=None,
                    help='RestorerConfig overrides as JSON (docs/config.md), e.g. \'{"sided_fill": {"gap": 3.0}}\' '
                         "or version-1 flat names")
    ap.add_argument("--fill", default="all", choices=["all", "trusted"])
    ap.add_argument("--real", action="store_true", help="(c) outlier shares on the real frames (needs open3d)")
    ap.add_argument("--no-sensor", action="store_true", help="skip (a) and (b)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    config = json.loads(args.config) if args.config else {}
    out = {"config": config, "fill": args.fill}
    if not args.no_sensor:
        rows = run_sensor(args.scenes, config, args.fill)
        out["sensor"] = rows
        print(f"{'scene':12s} {'rmse':>7s} {'rmse_holes':>10s} {'bridge %':>9s} {'edge_off %':>10s} {'wrong %':>8s} {'left %':>7s}")
        groups = [("held-out 10", lambda r: r["year"] != 2006), ("2006", lambda r: r["year"] == 2006),
                  ("all", lambda r: True)]
        for r in rows:
            print(f"{r['scene']:12s} {r['rmse']:7.3f} {r['rmse_holes']:10.3f} {100 * r['bridge']:9.2f} "
                  f"{100 * r['edge_off']:10.2f} {100 * r['wrong_side']:8.2f} {100 * r['holes_left']:7.2f}")
        for g, pick in groups:
            n = sum(map(pick, rows))
            if n:
                print(f"{'mean ' + g + f' ({n})':12s} {_mean(rows, 'rmse', pick):7.3f} {_mean(rows, 'rmse_holes', pick):10.3f} "
                      f"{100 * _mean(rows, 'bridge', pick):9.2f} {100 * _mean(rows, 'edge_off', pick):10.2f} "
                      f"{100 * _mean(rows, 'wrong_side', pick):8.2f} "
                      f"{100 * _mean(rows, 'holes_left', pick):7.2f}")
    if args.real:
        rows = run_real(config, args.fill)
        out["real"] = rows
        if rows:
            print(f"{'frame':8s} {'filled pts':>10s} {'outl. filled %':>14s} {'outl. measured %':>16s} {'left %':>7s}")
            for r in rows:
                print(f"{r['frame']:8s} {r['filled_points']:10d} {100 * r['outliers_filled']:14.2f} "
                      f"{100 * r['outliers_measured']:16.2f} {100 * r['holes_left']:7.2f}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
