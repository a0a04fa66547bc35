"""The window means of a stream's change test and state (:func:`~torch_depth_sr.stream.change._box_mean`): a numba
kernel.

``_box_mean`` pads, takes float64 cumulative sums along rows, differences them, pads again, sums along columns and
differences again: eight passes over every plane with a temporary for each, memory-bound on large frames (at
1376×1088 the change test's and the state's window means took about a tenth of a stream step). This kernel makes the
same running sums in the same order (one float64 sum from the first padded element, as ``torch.cumsum``) and the same
differences and division, so the means are the same bit for bit (tested): a row pass writes each row's window sums,
a column pass, by bands of columns, the window means. Rows, and bands, split across threads
(:func:`~torch_depth_sr.native.run_range`) with the same results for any thread count.
Compiled by LLVM at first use and cached on disk (``cache=True``).
"""
from __future__ import annotations

import numpy as np
import torch
from numba import njit

from ..native import run_range

__all__ = ["box_mean_cpu"]

_BAND = 64  # columns per task of the column pass
_MIN_ROWS = 16  # rows per task of the row pass below which one thread does it


@njit(cache=True, nogil=True)
def _rows(t0, t1, v, window, out):
    """Rows ``[t0, t1)`` of the ``P·H`` rows of ``v (P,H,W)``: ``out`` (float64) = the differences ``c[i + window] −
    c[i]`` of the running sum ``c`` of the row padded by ``window // 2 + 1`` zeros before and ``window // 2`` after."""
    h, w = v.shape[1], v.shape[2]
    p = window // 2
    n = w + 2 * p + 1
    c = np.empty(n)
    for t in range(t0, t1):
        plane = t // h
        y = t - plane * h
        acc = 0.0
        for k in range(n):
            j = k - p - 1
            if 0 <= j < w:
                acc += np.float64(v[plane, y, j])
            else:
                acc += 0.0
            c[k] = acc
        for i in range(w):
            out[plane, y, i] = c[i + window] - c[i]


@njit(cache=True, nogil=True)
def _columns(t0, t1, r, window, bands, out):
    """Tasks ``[t0, t1)`` of ``P·bands`` (plane, band of ``_BAND`` columns): the column pass of :func:`_rows` on the
    row sums ``r``, divided by ``window²``: the window means (float64)."""
    h, w = r.shape[1], r.shape[2]
    p = window // 2
    n = h + 2 * p + 1
    area = np.float64(window * window)
    c = np.empty((n, _BAND))
    for t in range(t0, t1):
        plane = t // bands
        x0 = (t - plane * bands) * _BAND
        x1 = min(w, x0 + _BAND)
        for x in range(x0, x1):
            c[0, x - x0] = 0.0
        for k in range(1, n):
            j = k - p - 1
            if 0 <= j < h:
                for x in range(x0, x1):
                    c[k, x - x0] = c[k - 1, x - x0] + r[plane, j, x]
            else:
                for x in range(x0, x1):
                    c[k, x - x0] = c[k - 1, x - x0] + 0.0
        for y in range(h):
            for x in range(x0, x1):
                out[plane, y, x] = (c[y + window, x - x0] - c[y, x - x0]) / area


def box_mean_cpu(v: torch.Tensor, window: int) -> torch.Tensor:
    """``change._box_mean(v, window)`` of ``v (B,C,H,W)`` float32 or float64 on the CPU, no gradient."""
    b, ch, h, w = v.shape
    a = np.ascontiguousarray(v.detach().numpy().reshape(b * ch, h, w))
    rows = np.empty(a.shape, dtype=np.float64)
    run_range(_rows, b * ch * h, a, window, rows, min_share=_MIN_ROWS)
    means = np.empty_like(rows)
    bands = -(-w // _BAND)
    run_range(_columns, b * ch * bands, rows, window, bands, means)
    return torch.from_numpy(means).view(b, ch, h, w).to(v.dtype)
