r"""Errors per region of the ground truth: where a method wins or loses (issue 11, item 2).

``python -m torch_depth_sr.evaluation.regions --track paper sensor --methods input jbf rgf full --json out.json``
labels the GT-known pixels of every scene into five disjoint regions, runs each method through
:func:`~torch_depth_sr.evaluation.methods.run_method` on the benchmark's own degraded inputs (the generator of
``torch-depth-sr bench``: same seeds, inputs below 0 treated as missing), and reports per region RMSE, MAE,
pixel share, the region's share of the method's total squared error, and, for each method against a
reference method (``--reference``, default ``rgf``), the region's share of the difference in mean squared
error. Summaries for all scenes, the ten held-out 2005/2003/2001 scenes and the eleven 2006 scenes.

Regions (:func:`label_regions`; all thresholds in grey levels of the stored ground truth and pixels, the
units every error of the benchmark is in). Checked in this order, the first that applies wins:

1. ``thin`` — thin foreground structures: a grey-level morphological opening of the GT with a 5×5 square
   (``THIN_WIDTH``; a square, not a disc, so the corners of wide objects stay) removes every structure that
   stands in front of its surroundings and holds no 5×5 square, i.e. is narrower than 5 px; pixels whose GT
   drops by more than ``JUMP`` = 4 grey levels under that opening are thin. Unknown GT pixels are set to the
   map's maximum for the opening, so they never make a neighbour thin.
2. ``edge`` — the edge band: GT-known pixels within 2 px of a depth discontinuity, exactly the band of the
   ``sensor`` track (:func:`~torch_depth_sr.degradations.edge_band`: \|∇ of the σ = 1 Gaussian-blurred GT\|
   > ``JUMP`` = 4, dilated by the disc x² + y² ≤ 4; the blur sees unknown GT as 0, so the border of unknown
   GT counts as an edge too — in Middlebury those pixels are mostly occlusions beside a depth edge). Pixels
   whose surface is too small for the fit below (a sliver between discontinuities) count as edge too.
3. ``curved`` — the Hessian of a local quadratic fit has an eigenvalue of magnitude > ``CURV`` = 0.02 grey
   levels/px² (a sphere cap of radius 40 px, in grey levels, has 1/40 = 0.025 at its top).
4. ``slanted`` — not curved and the fitted gradient magnitude > ``SLOPE`` = 0.05 grey levels/px (one grey level
   over 20 px).
5. ``planar`` — fronto-parallel: gradient ≤ ``SLOPE`` and curvature ≤ ``CURV``.

The local fit (:func:`local_quadratic`): a least-squares quadratic :math:`a + b\,u + c\,v + d\,u^2 + e\,v^2 + f\,uv`
in a Gaussian window (σ = ``FIT_SIGMA`` = 4 px, radius 12) over the pixels of the *same surface* only: the
GT-known pixels are split into surfaces by the discontinuity pixels (\|∇ blurred GT\| > ``JUMP``, or a
step > ``JUMP`` to a 4-neighbour) and the fit for a pixel uses its own connected surface (4-connected), so no
depth step bends a fit. The window is wide (σ = 4 px) so that the fit absorbs the 1-grey-level staircase of
the 8-bit quantisation: on the slanted planes of Venus the 95th percentile of the fitted curvature is 0.016,
below ``CURV`` (with σ = 2 it was 0.06: a quantised ramp looked curved).
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Optional, Sequence

import cv2
import numpy as np
import torch
from tqdm import tqdm

from ..degradations import edge_band

__all__ = ["REGIONS", "HELD_OUT", "label_regions", "local_quadratic", "region_errors", "summarise_regions",
           "label_figure", "main"]

REGIONS = ("planar", "slanted", "curved", "edge", "thin")  # label codes 1..5; 0 = GT unknown
HELD_OUT = ("Art", "Books", "Dolls", "Laundry", "Moebius", "Reindeer", "Cones", "Teddy", "Tsukuba", "Venus")
JUMP = 4.0  # grey levels: a depth discontinuity (the sensor track's edge threshold)
SLOPE = 0.05  # grey levels / px
CURV = 0.025  # grey levels / px²
THIN_WIDTH = 5  # px: structures narrower than this are thin
FIT_SIGMA = 4.0  # px
_COLOURS = {0: (0, 0, 0), 1: (200, 200, 200), 2: (60, 170, 60), 3: (200, 120, 30), 4: (40, 40, 220),
            5: (0, 220, 255)}  # BGR: unknown black, planar grey, slanted green, curved blue, edge red, thin yellow


def _discontinuities(gt: np.ndarray) -> np.ndarray:
    """Pixels where |∇ of the σ = 1 blurred GT| > JUMP (the core of the edge band, before dilation), or whose
    GT differs from a 4-neighbour's by more than JUMP (so no surface leaks across a step where the blurred
    gradient dips, e.g. at junctions)."""
    g = cv2.GaussianBlur(gt.astype(np.float32), (9, 9), 1.0, borderType=cv2.BORDER_REFLECT_101)
    gy, gx = np.gradient(g.astype(np.float64))
    out = np.hypot(gx, gy) > JUMP
    for axis in (0, 1):
        step = np.abs(np.diff(gt, axis=axis)) > JUMP
        lo = [slice(None)] * 2
        hi = [slice(None)] * 2
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        out[tuple(lo)] |= step
        out[tuple(hi)] |= step
    return out


def local_quadratic(gt: np.ndarray, known: np.ndarray, sigma: float = FIT_SIGMA
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per pixel ``(gx, gy, hxx, hyy, hxy)`` of a Gaussian-weighted quadratic fit on its own surface.

    Surfaces: 4-connected components of ``known`` minus the discontinuity pixels. Pixels outside any
    surface, or whose window holds too few surface pixels for a well-posed fit, get NaN.
    """
    gt = np.asarray(gt, np.float64)
    h, w = gt.shape
    r = int(math.ceil(3 * sigma))
    u = np.arange(-r, r + 1, dtype=np.float64)
    vv, uu = np.meshgrid(u, u, indexing="ij")  # rows (y), columns (x)
    gauss = np.exp(-(uu ** 2 + vv ** 2) / (2 * sigma ** 2))
    basis = [np.ones_like(uu), uu, vv, uu ** 2, vv ** 2, uu * vv]  # a, b (x), c (y), d (x²), e (y²), f (xy)
    out = np.full((5, h, w), np.nan)
    surface = known & ~_discontinuities(gt)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(surface.astype(np.uint8), connectivity=4)
    for k in range(1, n):
        x0, y0, bw, bh, area = stats[k]
        if area < 6:
            continue
        ya, yb, xa, xb = max(0, y0 - r), min(h, y0 + bh + r), max(0, x0 - r), min(w, x0 + bw + r)
        c = (lab[ya:yb, xa:xb] == k).astype(np.float64)
        g = gt[ya:yb, xa:xb] * c

        def corr(img, kern):
            return cv2.filter2D(img, cv2.CV_64F, kern, borderType=cv2.BORDER_CONSTANT)

        a_mat = np.empty(c.shape + (6, 6))
        for i in range(6):
            for j in range(i, 6):
                a_mat[..., i, j] = a_mat[..., j, i] = corr(c, gauss * basis[i] * basis[j])
        b_vec = np.stack([corr(g, gauss * basis[i]) for i in range(6)], -1)
        sel = c > 0
        a_sel, b_sel = a_mat[sel], b_vec[sel]
        ok = np.linalg.cond(a_sel) < 1e8
        theta = np.full((sel.sum(), 6), np.nan)
        if ok.any():
            theta[ok] = np.linalg.solve(a_sel[ok], b_sel[ok][..., None])[..., 0]
        sub = out[:, ya:yb, xa:xb]
        for i, val in enumerate((theta[:, 1], theta[:, 2], 2 * theta[:, 3], 2 * theta[:, 4], theta[:, 5])):
            sub[i][sel] = val
    return tuple(out)


def label_regions(gt: torch.Tensor | np.ndarray, known: torch.Tensor | np.ndarray | None = None) -> np.ndarray:
    """Region codes ``(H,W) uint8``: 0 GT unknown, then 1..5 = :data:`REGIONS` (see the module docstring).

    Args:
        gt: (H,W) ground truth (tensor or array, grey levels); 0 = unknown unless ``known`` is given.
        known: (H,W) bool, GT-known pixels (default ``gt > 0``).
    """
    gt = np.asarray(gt.detach().cpu().numpy() if isinstance(gt, torch.Tensor) else gt, np.float64).squeeze()
    if known is None:
        known = gt > 0
    known = np.asarray(known.detach().cpu().numpy() if isinstance(known, torch.Tensor) else known).squeeze() > 0
    known = known & np.isfinite(gt)
    gt = np.where(known, gt, 0.0)
    square = np.ones((THIN_WIDTH, THIN_WIDTH), np.uint8)
    filled = np.where(known, gt, gt[known].max() if known.any() else 0.0).astype(np.float32)
    opened = cv2.dilate(cv2.erode(filled, square, borderType=cv2.BORDER_REPLICATE), square,
                        borderType=cv2.BORDER_REPLICATE)
    thin = known & (gt - opened > JUMP)
    edge = edge_band(gt, known, JUMP) & ~thin
    gx, gy, hxx, hyy, hxy = local_quadratic(gt, known)
    half_tr, rad = (hxx + hyy) / 2, np.sqrt(((hxx - hyy) / 2) ** 2 + hxy ** 2)
    curv = np.abs(half_tr) + rad  # largest |eigenvalue| of the Hessian
    slope = np.hypot(gx, gy)
    with np.errstate(invalid="ignore"):
        curved = curv > CURV
        slanted = ~curved & (slope > SLOPE)
    labels = np.zeros(gt.shape, np.uint8)
    rest = known & ~thin & ~edge
    labels[rest] = 1
    labels[rest & slanted] = 2
    labels[rest & curved] = 3
    labels[rest & ~np.isfinite(curv)] = 4  # no fit possible: a sliver between discontinuities
    labels[edge] = 4
    labels[thin] = 5
    return labels


def region_errors(pred: torch.Tensor | np.ndarray, gt: torch.Tensor | np.ndarray, labels: np.ndarray) -> dict:
    """``{region: {"n", "sse", "sae"}}`` of ``pred − gt`` over each region (float64 sums)."""
    p = np.asarray(pred.detach().cpu().numpy() if isinstance(pred, torch.Tensor) else pred, np.float64).squeeze()
    g = np.asarray(gt.detach().cpu().numpy() if isinstance(gt, torch.Tensor) else gt, np.float64).squeeze()
    e = p - g
    out = {}
    for code, name in enumerate(REGIONS, start=1):
        sel = labels == code
        out[name] = {"n": int(sel.sum()), "sse": float((e[sel] ** 2).sum()), "sae": float(np.abs(e[sel]).sum())}
    sel = labels > 0
    out["all"] = {"n": int(sel.sum()), "sse": float((e[sel] ** 2).sum()), "sae": float(np.abs(e[sel]).sum())}
    return out


def summarise_regions(rows: list[dict], reference: str = "rgf") -> list[dict]:
    """Per (track, subset, method, region): the means over scenes (each scene weighs the same, as in the bench).

    ``rmse``/``mae``: mean over scenes of the region's per-scene value (scenes where the region has pixels);
    ``share``: mean pixel share; ``sse_share``: mean over scenes of the region's share of the method's squared
    error; ``dmse``: mean over scenes of (the method's − ``reference``'s) squared error in the region divided
    by the scene's pixel count — these add up over the regions to the difference in MSE — and ``dmse_share``
    its share of the total difference.
    """
    out = []
    tracks = dict.fromkeys(r["track"] for r in rows)
    for track in tracks:
        trows = [r for r in rows if r["track"] == track]
        scenes = list(dict.fromkeys(r["scene"] for r in trows))
        subsets = {"all": scenes, "held-out": [s for s in scenes if s in HELD_OUT],
                   "2006": [s for s in scenes if s not in HELD_OUT]}
        by = {(r["scene"], r["method"]): r["regions"] for r in trows}
        for subset, names in subsets.items():
            if not names:
                continue
            for method in dict.fromkeys(r["method"] for r in trows):
                gaps = {}
                for region in REGIONS + ("all",):
                    vals = [by[(s, method)][region] for s in names if (s, method) in by]
                    have = [v for v in vals if v["n"] > 0]
                    alls = [by[(s, method)]["all"] for s in names if (s, method) in by]
                    agg = {"track": track, "subset": subset, "scenes": len(vals), "method": method, "region": region,
                           "share": float(np.mean([v["n"] / a["n"] for v, a in zip(vals, alls)])),
                           "rmse": float(np.mean([math.sqrt(v["sse"] / v["n"]) for v in have])) if have else None,
                           "mae": float(np.mean([v["sae"] / v["n"] for v in have])) if have else None,
                           "sse_share": float(np.mean([v["sse"] / a["sse"] for v, a in zip(vals, alls) if a["sse"] > 0]))}
                    if method != reference and all((s, reference) in by for s in names):
                        d = [(by[(s, method)][region]["sse"] - by[(s, reference)][region]["sse"])
                             / by[(s, method)]["all"]["n"] for s in names]
                        agg["dmse"] = gaps[region] = float(np.mean(d))
                    out.append(agg)
                if gaps and gaps["all"] != 0:
                    for agg in out[-len(REGIONS) - 1:]:
                        agg["dmse_share"] = agg["dmse"] / gaps["all"]
    return out


def label_figure(path: Path | str, rgb: torch.Tensor | np.ndarray, gt: torch.Tensor | np.ndarray,
                 labels: np.ndarray) -> Path:
    """PNG: colour, ground truth and the region labels (unknown black, planar grey, slanted green, curved
    blue, edge red, thin yellow)."""
    from ..figures import depth_to_bgr, mosaic, rgb_to_bgr, write_png

    g = np.asarray(gt.detach().cpu().numpy() if isinstance(gt, torch.Tensor) else gt, np.float32).squeeze()
    vals = g[labels > 0]
    lab = np.zeros(labels.shape + (3,), np.uint8)
    for code, colour in _COLOURS.items():
        lab[labels == code] = colour
    caption = "regions: " + " ".join(f"{n}={c}" for n, c in zip(REGIONS, ("grey", "green", "blue", "red", "yellow")))
    return write_png(path, mosaic([[rgb_to_bgr(rgb), depth_to_bgr(g, float(np.percentile(vals, 0.5)),
                                                                   float(np.percentile(vals, 99.5)), missing=labels == 0),
                                    lab]], [["colour", "ground truth", caption]], max_width=520))


def _table(summary: list[dict], track: str, subset: str, methods: list[str], reference: str) -> str:
    """Two Markdown tables: RMSE / MAE per region and method; each region's share of the squared error and of
    the gap in MSE to ``reference``."""
    rows = [r for r in summary if r["track"] == track and r["subset"] == subset]
    if not rows:
        return ""
    get = {(r["method"], r["region"]): r for r in rows}
    others = [m for m in methods if m not in (reference, "input")]
    fmt = lambda v: "–" if v is None else f"{v:.3f}"  # noqa: E731
    head1 = ["region", "pixels"] + [f"{m} RMSE / MAE" for m in methods]
    head2 = (["region"] + [f"SE share {m}" for m in methods if m != "input"]
             + [f"ΔMSE {m} − {reference} (share of the gap)" for m in others])
    t1 = [f"{track}, {subset} ({rows[0]['scenes']} scenes)", "", "| " + " | ".join(head1) + " |",
          "|" + "---|" * len(head1)]
    t2 = ["", "| " + " | ".join(head2) + " |", "|" + "---|" * len(head2)]
    for region in REGIONS + ("all",):
        cells = [region, f"{100 * get[(methods[0], region)]['share']:.1f} %"]
        cells += [f"{fmt(get[(m, region)]['rmse'])} / {fmt(get[(m, region)]['mae'])}" for m in methods]
        t1.append("| " + " | ".join(cells) + " |")
        cells = [region] + [f"{100 * get[(m, region)]['sse_share']:.1f} %" for m in methods if m != "input"]
        for m in others:
            g = get[(m, region)]
            cells.append(f"{g['dmse']:+.3f} ({100 * g['dmse_share']:.0f} %)" if "dmse_share" in g else "–")
        t2.append("| " + " | ".join(cells) + " |")
    return "\n".join(t1 + t2)


def main(argv: Optional[Sequence[str]] = None) -> int:
    from .._data_root import data_root
    from .bench import _parse_config, _samples
    from .methods import run_method
    from .report import metadata

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--track", nargs="*", default=["paper"], choices=["paper", "sensor"])
    ap.add_argument("--methods", nargs="*", default=["input", "jbf", "rgf", "full"])
    ap.add_argument("--scenes", nargs="*", default=None, help="scene names (default: all 21)")
    ap.add_argument("--config", default=None,
                    help="JSON of RestorerConfig overrides (as bench --config; docs/config.md): adds a method "
                         "'full+config' (full with them)")
    ap.add_argument("--reference", default="rgf", help="method the others' squared-error gap is measured against")
    ap.add_argument("--json", default=None, help="write per-scene rows, the summary and metadata here")
    ap.add_argument("--figure", default=None, help="PNG of the region labels of the first scene (or --figure-scene)")
    ap.add_argument("--figure-scene", default=None)
    ap.add_argument("--data", default=None)
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args(argv)
    config = _parse_config(args.config)
    methods = list(args.methods) + (["full+config"] if config else [])
    root = Path(args.data) if args.data else data_root()
    rows, labels_cache, figure_done = [], {}, False
    for track in args.track:
        items = list(_samples(track, root, args.scenes, None))
        bar = tqdm(total=len(items) * len(methods), desc=f"regions {track}", unit="run")
        for rec, sample in items:
            if rec.name not in labels_cache:
                labels_cache[rec.name] = label_regions(sample["gt"][0], sample["mask"][0] > 0)
            labels = labels_cache[rec.name]
            if args.figure and not figure_done and (args.figure_scene in (None, rec.name)):
                label_figure(args.figure, sample["rgb"], sample["gt"], labels)
                figure_done = True
            for m in methods:
                if m == "full+config":
                    pred = run_method("full", sample, args.device, config, track=track)
                else:
                    pred = run_method(m, sample, args.device, None, track=track)
                rows.append({"track": track, "scene": rec.name, "method": m,
                             "regions": region_errors(pred, sample["gt"], labels)})
                bar.update(1)
        bar.close()
    summary = summarise_regions(rows, args.reference)
    for track in args.track:
        for subset in ("all", "held-out", "2006"):
            text = _table(summary, track, subset, methods, args.reference)
            if text:
                print(text + "\n")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        meta = metadata(args.device)
        meta.update(tracks=args.track, methods=methods, config_overrides=config or {}, reference=args.reference,
                    thresholds=dict(JUMP=JUMP, SLOPE=SLOPE, CURV=CURV, THIN_WIDTH=THIN_WIDTH, FIT_SIGMA=FIT_SIGMA))
        Path(args.json).write_text(json.dumps({"metadata": meta, "summary": summary, "rows": rows}, indent=1))
        print(f"json: {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
