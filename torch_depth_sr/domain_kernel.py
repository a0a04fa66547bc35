"""The boxes of the domain-transform filter (:func:`~torch_depth_sr.guided_filters.domain_transform_filter`):
numba kernels of ``guided_filters._box_bounds`` (by counting) and ``guided_filters._box``.

The box ends count, for each pixel, the neighbours within the box's radius in warped coordinates, with the
differences and compares of the torch path in the same dtype: the same ends. The torch path makes ``2·reach``
passes over the planes, with a temporary for each.

A pass replaces each value by the mean of its box ``lo <= j < hi`` along rows or columns, from an exclusive
cumulative sum. The torch path builds the sum, pads it, gathers both ends and divides: six passes over the planes and
four temporaries; this kernel keeps one row's (or one band of columns') sums and writes the means. The sums are
accumulated in the same order as ``torch.cumsum`` (one running float64 sum from the first element) and the mean is
the same division, so the outputs are the same bit for bit (tested). Rows, and bands of columns, split across
threads (:func:`~torch_depth_sr.native.run_range`) with the same results for any thread count.
Compiled by LLVM at first use and cached on disk (``cache=True``).
"""
from __future__ import annotations

import numpy as np
import torch
from numba import njit

from .native import run_range

__all__ = ["bounds_cpu", "box_cpu"]

_BAND = 64  # columns per task of a column pass
_MIN_ROWS = 16  # rows per task of a row pass below which one thread does the pass


@njit(cache=True, nogil=True)
def _rows(t0, t1, v, lo, hi, out):
    """Rows ``[t0, t1)`` of the ``P·H`` rows of ``v (P,H,W)`` float64 (``P = B·C`` planes); ``lo``, ``hi``
    ``(B,H,W)`` int64 box ends into the exclusive sum; writes ``out (P,H,W)``."""
    h, n = v.shape[1], v.shape[2]
    c = v.shape[0] // lo.shape[0]
    cs = np.empty(n + 1)
    cs[0] = 0.0
    for t in range(t0, t1):
        p = t // h
        y = t - p * h
        b = p // c
        acc = 0.0
        for i in range(n):
            acc += v[p, y, i]
            cs[i + 1] = acc
        for i in range(n):
            a = lo[b, y, i]
            e = hi[b, y, i]
            out[p, y, i] = (cs[e] - cs[a]) / (e - a)


@njit(cache=True, nogil=True)
def _columns(t0, t1, v, lo, hi, out, bands):
    """Tasks ``[t0, t1)`` of ``P·bands`` (plane, band of ``_BAND`` columns): the column pass of :func:`_rows`."""
    h, w = v.shape[1], v.shape[2]
    c = v.shape[0] // lo.shape[0]
    cs = np.empty((h + 1, _BAND))
    for t in range(t0, t1):
        p = t // bands
        x0 = (t - p * bands) * _BAND
        x1 = min(w, x0 + _BAND)
        b = p // c
        for x in range(x0, x1):
            cs[0, x - x0] = 0.0
        for y in range(h):
            for x in range(x0, x1):
                cs[y + 1, x - x0] = cs[y, x - x0] + v[p, y, x]
        for y in range(h):
            for x in range(x0, x1):
                a = lo[b, y, x]
                e = hi[b, y, x]
                out[p, y, x] = (cs[e, x - x0] - cs[a, x - x0]) / (e - a)


@njit(cache=True, nogil=True)
def _bounds(t0, t1, c, radius, reach, along_rows, lo, hi):
    """Rows ``[t0, t1)`` of the ``B·H`` rows: the box ends of each pixel along rows (``along_rows``) or columns,
    ``guided_filters._box_bounds``' count of the ``k <= reach`` neighbours ``i ± k`` with ``|c_i − c_{i±k}| <=
    radius[b]`` (the same differences and compares in ``c``'s dtype). Loops over a row innermost (vectorised)."""
    h, w = c.shape[1], c.shape[2]
    before = np.empty(w, dtype=np.int64)
    after = np.empty(w, dtype=np.int64)
    for t in range(t0, t1):
        b = t // h
        y = t - b * h
        r = radius[b]
        before[:] = 0
        after[:] = 0
        for k in range(1, reach + 1):
            if along_rows:
                for x in range(w - k):
                    near = (c[b, y, x + k] - c[b, y, x]) <= r  # pixels x and x + k
                    after[x] += near
                    before[x + k] += near
            else:
                if y + k < h:
                    for x in range(w):
                        after[x] += (c[b, y + k, x] - c[b, y, x]) <= r
                if y - k >= 0:
                    for x in range(w):
                        before[x] += (c[b, y, x] - c[b, y - k, x]) <= r
        for x in range(w):
            i = x if along_rows else y
            lo[b, y, x] = i - before[x]
            hi[b, y, x] = i + after[x] + 1


def bounds_cpu(coords: torch.Tensor, radius: torch.Tensor, reach: int, dim: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``guided_filters._box_bounds`` by counting (``reach`` neighbours on each side) of ``coords (B,1,H,W)``,
    ``radius (B,1,1,1)`` in its dtype: ``(lo, hi)`` (B,1,H,W) int64."""
    b, _, h, w = coords.shape
    c = np.ascontiguousarray(coords.detach().numpy().reshape(b, h, w))
    r = np.ascontiguousarray(radius.detach().expand(b, 1, 1, 1).numpy().reshape(b))
    lo = np.empty((b, h, w), dtype=np.int64)
    hi = np.empty_like(lo)
    run_range(_bounds, b * h, c, r, reach, dim in (-1, 3), lo, hi, min_share=_MIN_ROWS)
    return torch.from_numpy(lo).view(b, 1, h, w), torch.from_numpy(hi).view(b, 1, h, w)


def box_cpu(values: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor, dim: int) -> torch.Tensor:
    """``guided_filters._box`` of float64 ``values (B,C,H,W)`` with the box ends ``lo``, ``hi`` (B,1,H,W) int64
    along ``dim`` (-1 or -2); no gradient."""
    b, c, h, w = values.shape
    v = np.ascontiguousarray(values.detach().numpy().reshape(b * c, h, w))
    lo_ = np.ascontiguousarray(lo.numpy().reshape(b, h, w))
    hi_ = np.ascontiguousarray(hi.numpy().reshape(b, h, w))
    out = np.empty_like(v)
    if dim in (-1, 3):
        run_range(_rows, b * c * h, v, lo_, hi_, out, min_share=_MIN_ROWS)
    else:
        bands = -(-w // _BAND)
        run_range(_columns, b * c * bands, v, lo_, hi_, out, bands)
    return torch.from_numpy(out).view(b, c, h, w)
