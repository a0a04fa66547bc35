"""PNG figures with OpenCV: depth and error maps on shared colour scales, labelled mosaics."""
from __future__ import annotations

from pathlib import Path
from typing import Optional, Sequence, Union

import cv2
import numpy as np
import torch

__all__ = ["depth_to_bgr", "error_to_bgr", "rgb_to_bgr", "mosaic", "write_png", "comparison_figure"]

ArrayLike = Union[torch.Tensor, np.ndarray]  # an image as a tensor or an array; leading size-1 axes are dropped


def _np2d(x: ArrayLike) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        x = x.detach().float().cpu().numpy()
    x = np.asarray(x, dtype=np.float32)
    while x.ndim > 2:
        x = x[0]
    return x


def depth_to_bgr(depth: ArrayLike, vmin: float, vmax: float, missing: Optional[ArrayLike] = None) -> np.ndarray:
    """Colour-map depth with a fixed range (turbo); missing pixels (0/NaN or ``missing``) are black."""
    d = _np2d(depth)
    bad = ~np.isfinite(d) | (d <= 0)
    if missing is not None:
        bad |= _np2d(missing) > 0
    u8 = np.clip((np.nan_to_num(d) - vmin) / max(vmax - vmin, 1e-12) * 255, 0, 255).astype(np.uint8)
    img = cv2.applyColorMap(u8, cv2.COLORMAP_TURBO)
    img[bad] = 0
    return img


def error_to_bgr(pred: ArrayLike, gt: ArrayLike, valid: ArrayLike, vmax: float) -> np.ndarray:
    """Absolute error |pred − gt| on a fixed scale [0, vmax] (hot), unknown GT grey."""
    e = np.abs(_np2d(pred) - _np2d(gt))
    u8 = np.clip(e / max(vmax, 1e-12) * 255, 0, 255).astype(np.uint8)
    img = cv2.applyColorMap(u8, cv2.COLORMAP_HOT)
    img[_np2d(valid) <= 0] = 96
    return img


def rgb_to_bgr(rgb: ArrayLike) -> np.ndarray:
    """(3,H,W) or (1,3,H,W) float in [0,1] -> H×W×3 uint8 BGR."""
    if isinstance(rgb, torch.Tensor):
        rgb = rgb.detach().float().cpu().numpy()
    rgb = np.asarray(rgb)
    while rgb.ndim > 3:
        rgb = rgb[0]
    img = (np.clip(rgb.transpose(1, 2, 0), 0, 1) * 255).round().astype(np.uint8)
    return cv2.cvtColor(img, cv2.COLOR_RGB2BGR)


def mosaic(rows: Sequence[Sequence[np.ndarray]], labels: Sequence[Sequence[str]], max_width: int = 420) -> np.ndarray:
    """Grid of equally sized panels with a caption strip above each."""
    h, w = rows[0][0].shape[:2]
    scale = min(1.0, max_width / w)
    size = (int(round(w * scale)), int(round(h * scale)))
    n_cols = max(len(r) for r in rows)
    out_rows = []
    for r, labs in zip(rows, labels):
        cells = []
        for i in range(n_cols):
            if i < len(r):
                p = cv2.resize(r[i], size, interpolation=cv2.INTER_NEAREST)
                cap = np.full((22, size[0], 3), 255, np.uint8)
                cv2.putText(cap, labs[i], (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
                cells.append(np.vstack([cap, p]))
            else:
                cells.append(np.full((size[1] + 22, size[0], 3), 255, np.uint8))
        out_rows.append(np.hstack(cells))
    return np.vstack(out_rows)


def write_png(path: Path | str, img: np.ndarray) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), img):
        raise OSError(f"could not write PNG {path}")
    return path


def comparison_figure(path: Path | str, rgb: ArrayLike, degraded: ArrayLike, gt: ArrayLike, valid: ArrayLike,
                      results: dict, err_max: float | None = None, ref_name: str = "gt") -> Path:
    """Paper Figure 4-1 layout: colour, input, GT, each method; error maps in the second row."""
    g = _np2d(gt)
    v = _np2d(valid) > 0
    vals = g[v] if v.any() else g[np.isfinite(g)]
    vmin, vmax = float(np.percentile(vals, 0.5)), float(np.percentile(vals, 99.5))
    err_max = err_max or max((vmax - vmin) * 0.05, 1e-6)
    top = [rgb_to_bgr(rgb), depth_to_bgr(degraded, vmin, vmax), depth_to_bgr(gt, vmin, vmax, missing=~v)]
    top_l = ["colour", "input", "ground truth" if ref_name == "gt" else ref_name]
    bot = [np.full_like(top[0], 255), error_to_bgr(np.where(_np2d(degraded) > 0, _np2d(degraded), 0), g, v, err_max),
           np.full_like(top[0], 255)]
    bot_l = ["", f"|input-{ref_name}| (0..{err_max:.3g})", ""]
    for name, pred in results.items():
        top.append(depth_to_bgr(pred, vmin, vmax))
        top_l.append(name)
        bot.append(error_to_bgr(pred, g, v, err_max))
        bot_l.append(f"|{name}-{ref_name}|")
    return write_png(path, mosaic([top, bot], [top_l, bot_l]))
