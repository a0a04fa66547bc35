"""Procedural RGB-D scenes for training and tests (seeded, fast).

A scene is a slanted background plane plus, composited front to back by disparity (larger =
nearer), fronto-parallel and slanted rectangles, spheres, cylinders and thin structures (poles
and bars). Each object has its own base colour and texture, so colour edges follow depth edges;
the background also carries painted stripes and text-like glyph marks whose colour edges have
NO depth edge (the case a colour-guided method must not copy into depth).

Units: 8-bit-disparity-like grey levels, values within about [20, 230], ``scale = 3.0``
(as the Middlebury 2005/2006 third-size files). The whole ground truth is known (``mask`` = 1).
"""

from __future__ import annotations

from typing import Callable, Optional

import numpy as np
import torch
from torch.utils.data import Dataset

from torch_depth_sr.errors import DepthSRError

D_MIN, D_MAX = 20.0, 230.0


def _texture(rng, h, w, yy, xx):
    kind = rng.integers(0, 3)
    if kind == 0:  # smooth gradient shading
        a, b = rng.uniform(-1, 1, 2)
        return 0.15 * (a * yy / max(h, 1) + b * xx / max(w, 1))
    if kind == 1:  # sinusoidal weave
        f1, f2 = rng.uniform(0.05, 0.3, 2)
        return 0.08 * np.sin(f1 * xx + rng.uniform(0, 6.3)) * np.sin(f2 * yy)
    return 0.0  # flat


def make_scene(height: int = 480, width: int = 640, seed: int = 0, n_objects: int = None) -> dict:
    """Make one procedural RGB-D scene.

    Args:
        height, width: image size (>= 16).
        seed: any int; the scene is a pure function of (height, width, seed, n_objects).
        n_objects: number of foreground objects (default: random 5..10).

    Returns:
        dict with ``rgb`` (3,H,W) float32 in [0,1], ``gt`` (1,H,W) float32 in about [20, 230],
        ``depth`` (= gt, a clean copy; degrade it with the protocols), ``mask`` (1,H,W) ones,
        ``labels`` (1,H,W) int64 object id (0 = background), ``paint`` (1,H,W) float32 (1 on
        painted marks: colour edges without depth edges), ``scale`` 3.0, ``name``
        ``'synthetic_<seed>'``, ``dataset`` ``'synthetic'``.

    Examples:
        >>> s = make_scene(48, 64, seed=1)
        >>> s['rgb'].shape, s['gt'].shape, bool(s['gt'].min() >= 20)
        (torch.Size([3, 48, 64]), torch.Size([1, 48, 64]), True)
    """
    if height < 16 or width < 16:
        raise DepthSRError(f"make_scene needs height, width >= 16, got {height}x{width}")
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, height, width])
    h, w = int(height), int(width)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)  # (H, W) each

    # background: slanted plane, far
    d0 = rng.uniform(30, 70)
    gx, gy = rng.uniform(-25, 25) / w, rng.uniform(0, 40) / h
    disp = (d0 + gx * (xx - w / 2) + gy * yy).astype(np.float32)
    disp = np.clip(disp, D_MIN, None)
    labels = np.zeros((h, w), np.int64)
    base = rng.uniform(0.2, 0.8, 3).astype(np.float32)
    rgb = np.empty((h, w, 3), np.float32)
    rgb[:] = base
    rgb += np.asarray(_texture(rng, h, w, yy, xx), np.float32)[..., None]

    # painted marks on the background: stripes and glyph-like strokes (no depth change)
    paint = np.zeros((h, w), bool)
    for _ in range(rng.integers(2, 5)):
        if rng.random() < 0.5:  # stripe band
            x0 = rng.integers(0, w)
            period, width_ = rng.integers(6, 20), rng.integers(2, 6)
            y0, y1 = sorted(rng.integers(0, h, 2))
            x1 = min(w, x0 + rng.integers(w // 8, w // 3))
            sl = (slice(y0, y1 + 1), slice(x0, x1))
            m = ((xx[sl] - x0) % period) < width_
        else:  # "text": a row of small rectangular glyph strokes
            gh = int(rng.integers(max(3, h // 60), max(4, h // 20)))
            y0 = int(rng.integers(0, max(1, h - gh)))
            x0 = int(rng.integers(0, max(1, w - 8 * gh)))
            x1 = min(w, x0 + int(rng.integers(4, 12)) * gh)
            sl = (slice(y0, y0 + gh), slice(x0, x1))
            cell = ((xx[sl] - x0) // max(1, gh // 2)).astype(np.int64)
            m = (rng.random(64)[cell % 64] < 0.55) & (((yy[sl] - y0) % gh) < gh - 1)
        colour = rng.uniform(0, 1, 3).astype(np.float32)
        rgb[sl][m] = colour
        paint[sl] |= m

    n_obj = int(rng.integers(5, 11)) if n_objects is None else int(n_objects)
    order = np.sort(rng.uniform(80, 200, n_obj))  # painter's order: far to near
    for k, dnear in enumerate(order, start=1):
        kind = rng.choice(["rect", "slanted", "sphere", "cylinder", "pole", "bar"])
        cy, cx = rng.uniform(0.1, 0.9) * h, rng.uniform(0.1, 0.9) * w
        if kind in ("rect", "slanted"):
            hh, hw = rng.uniform(0.05, 0.25) * h, rng.uniform(0.05, 0.25) * w
            y0, y1 = int(max(0, cy - hh)), int(min(h, cy + hh))
            x0, x1 = int(max(0, cx - hw)), int(min(w, cx + hw))
            sl = (slice(y0, y1), slice(x0, x1))
            m = np.ones((y1 - y0, x1 - x0), bool)
            dv = np.full(m.shape, dnear, np.float32)
            if kind == "slanted":
                a, b = rng.uniform(-0.4, 0.4, 2)
                dv = dv + a * (xx[sl] - cx) + b * (yy[sl] - cy)
        elif kind in ("sphere", "cylinder"):
            r = rng.uniform(0.05, 0.18) * min(h, w)
            y0, y1 = int(max(0, cy - r)), int(min(h, cy + r + 1))
            x0, x1 = int(max(0, cx - r)), int(min(w, cx + r + 1))
            if kind == "cylinder":
                y0, y1 = int(max(0, cy - 3 * r)), int(min(h, cy + 3 * r))
            sl = (slice(y0, y1), slice(x0, x1))
            dx, dy = xx[sl] - cx, yy[sl] - cy
            q = (dx ** 2 + dy ** 2) / r ** 2 if kind == "sphere" else (dx ** 2) / r ** 2 + 0 * dy
            m = q < 1.0
            dv = (dnear - 0.5 * r + 0.5 * r * np.sqrt(np.clip(1.0 - q, 0, 1))).astype(np.float32)
        else:  # thin structures
            t = int(rng.integers(2, 6))
            if kind == "pole":
                x0 = int(np.clip(cx, 0, w - t)); x1 = x0 + t
                y0, y1 = int(rng.uniform(0, 0.4) * h), int(rng.uniform(0.6, 1.0) * h)
            else:
                y0 = int(np.clip(cy, 0, h - t)); y1 = y0 + t
                x0, x1 = int(rng.uniform(0, 0.4) * w), int(rng.uniform(0.6, 1.0) * w)
            sl = (slice(y0, y1), slice(x0, x1))
            m = np.ones((y1 - y0, x1 - x0), bool)
            dv = np.full(m.shape, dnear, np.float32)
        if m.size == 0:
            continue
        m = m & (dv > disp[sl])  # z-buffer: nearer wins
        disp[sl][m] = dv[m]
        labels[sl][m] = k
        colour = rng.uniform(0.05, 0.95, 3).astype(np.float32)
        tex = np.asarray(_texture(rng, h, w, yy[sl], xx[sl]), np.float32)
        patch = colour + (tex[..., None] if tex.ndim else tex)  # (h, w, 3)
        patch = np.broadcast_to(patch, m.shape + (3,))
        rgb[sl][m] = patch[m]

    disp = np.clip(disp, D_MIN, D_MAX).astype(np.float32)
    rgb = np.clip(rgb, 0.0, 1.0)
    gt = torch.from_numpy(disp)[None]  # (1, H, W)
    return {
        "rgb": torch.from_numpy(np.ascontiguousarray(rgb.transpose(2, 0, 1))),  # (3, H, W)
        "gt": gt,
        "depth": gt.clone(),
        "mask": torch.ones_like(gt),
        "labels": torch.from_numpy(labels)[None],
        "paint": torch.from_numpy(paint.astype(np.float32))[None],
        "scale": 3.0,
        "name": f"synthetic_{int(seed)}",
        "dataset": "synthetic",
    }


class SyntheticScenes(Dataset):
    """``n`` procedural scenes of ``size`` = (H, W); scene ``i`` uses seed ``seed * 1_000_003 + i``.

    Optionally applies ``transform`` (e.g. a degradation from :mod:`torch_depth_sr.evaluation`).
    """

    def __init__(self, n: int = 100, size: int | tuple[int, int] = (128, 128), seed: int = 0,
                 transform: Optional[Callable[[dict], dict]] = None) -> None:
        if n < 0:
            raise DepthSRError(f"n must be >= 0, got {n}")
        if isinstance(size, int):
            size = (size, size)
        self.n, self.size, self.seed, self.transform = int(n), (int(size[0]), int(size[1])), int(seed), transform

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, i: int) -> dict:
        if not -self.n <= i < self.n:
            raise IndexError(f"index {i} out of range for {self.n} scenes")
        i = i % self.n
        s = make_scene(self.size[0], self.size[1], seed=self.seed * 1_000_003 + i)
        return self.transform(s) if self.transform is not None else s


__all__ = ["SyntheticScenes", "make_scene"]
