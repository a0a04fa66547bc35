"""The shift test's window sums (:func:`~torch_depth_sr.stream.shift.shifted_windows`) as a numba kernel, at the
pixels whose window departs only.

The torch path sums nine error planes over every window, 225 whole-frame additions; only the windows that depart
need them (a few per cent of a frame where something moved, none in a still scene). Each sum is taken in float64, one
offset after another, rows then columns, over the same float32 or float64 errors as the torch path. A shifted sum
stops once it reaches the bound, since the errors are not negative: the same verdicts bit for bit (tested). Rows
split across threads (:func:`~torch_depth_sr.native.run_range`). Compiled by LLVM at first use and cached on disk
(``cache=True``).
"""
from __future__ import annotations

import numpy as np
import torch
from numba import njit

from ..native import run_range
from ..dilate_kernel import dilate_planes

__all__ = ["shifted_windows_cpu"]

_MIN_ROWS = 16  # rows per task below which one thread does them


@njit(cache=True, nogil=True, error_model="numpy")
def _window_error(b, i, j, dy, dx, y, observed, previous, noise, half, clip, bound):
    """The summed error of the window at ``(b, i, j)`` against ``previous`` shifted by ``(dy, dx)`` (replicated at
    the border), in float64; stops once the sum reaches ``bound``."""
    h, w = y.shape[1], y.shape[2]
    total = 0.0
    for ii in range(i - half, i + half + 1):
        if ii < 0 or ii >= h:
            continue
        pi = min(max(ii + dy, 0), h - 1)
        for jj in range(j - half, j + half + 1):
            if jj < 0 or jj >= w or not observed[b, ii, jj] > 0:
                continue
            pj = min(max(jj + dx, 0), w - 1)
            e = abs(y[b, ii, jj] - previous[b, pi, pj]) / noise[b, ii, jj]
            if e > clip:
                e = clip
            total += np.float64(e)
        if total >= bound:
            return total
    return total


@njit(cache=True, nogil=True, error_model="numpy")
def _errors(t0, t1, y, observed, previous, noise, near, clip, still, low):
    """Rows ``[t0, t1)`` of the ``B·H`` rows, at the measured pixels of ``near``: ``still`` = the error against
    ``previous`` where it was, ``low`` = the smallest error against its nine one-pixel shifts (that one included),
    each as :func:`_window_error` adds it (float64)."""
    h, w = y.shape[1], y.shape[2]
    for t in range(t0, t1):
        b = t // h
        i = t - b * h
        for j in range(w):
            if not (near[b, i, j] and observed[b, i, j] > 0):
                continue
            best = np.inf
            for dy in range(-1, 2):
                pi = min(max(i + dy, 0), h - 1)
                for dx in range(-1, 2):
                    pj = min(max(j + dx, 0), w - 1)
                    e = abs(y[b, i, j] - previous[b, pi, pj]) / noise[b, i, j]
                    if e > clip:
                        e = clip
                    v = np.float64(e)
                    if dy == 0 and dx == 0:
                        still[b, i, j] = v
                    if v < best:
                        best = v
            low[b, i, j] = best


@njit(cache=True, nogil=True, error_model="numpy")
def _window_sum(b, i, j, observed, plane, half):
    """The sum of ``plane`` over the measured pixels of the window at ``(b, i, j)``, in :func:`_window_error`'s
    order."""
    h, w = plane.shape[1], plane.shape[2]
    total = 0.0
    for ii in range(max(i - half, 0), min(i + half + 1, h)):
        for jj in range(max(j - half, 0), min(j + half + 1, w)):
            if observed[b, ii, jj] > 0:
                total += plane[b, ii, jj]
    return total


@njit(cache=True, nogil=True, error_model="numpy")
def _rows(t0, t1, y, observed, previous, noise, departs, ratio, half, clip, still, low, out):
    """Rows ``[t0, t1)`` of the ``B·H`` rows."""
    h, w = y.shape[1], y.shape[2]
    for t in range(t0, t1):
        b = t // h
        i = t - b * h
        for j in range(w):
            out[b, i, j] = False
            if not departs[b, i, j]:
                continue
            bound = ratio * _window_sum(b, i, j, observed, still, half)
            # each pixel's smallest error over the shifts, added in the same order, is at most every shifted sum
            # (rounding is monotone): when even it reaches the bound, no shift matches better
            if _window_sum(b, i, j, observed, low, half) >= bound:
                continue
            for dy in range(-1, 2):
                for dx in range(-1, 2):
                    if (dy != 0 or dx != 0) and not out[b, i, j]:
                        if _window_error(b, i, j, dy, dx, y, observed, previous, noise, half, clip, bound) < bound:
                            out[b, i, j] = True


def shifted_windows_cpu(y: torch.Tensor, observed: torch.Tensor, previous: torch.Tensor, noise: torch.Tensor,
                        departs: torch.Tensor, ratio: float, window: int, clip: float) -> torch.Tensor:
    """``shifted_windows``' verdicts for (B,1,H,W) tensors of one float dtype on the CPU (``departs`` bool), no
    gradient."""
    b, _, h, w = y.shape
    half = window // 2
    arrays = [np.ascontiguousarray(t.detach().reshape(b, h, w).numpy()) for t in (y, observed, previous, noise)]
    mask = np.ascontiguousarray(departs.detach().reshape(b, h, w).numpy())
    near = np.empty_like(mask)  # the pixels of the departing windows
    dilate_planes(mask.view(np.uint8), half, near)
    still, low = np.zeros((b, h, w)), np.zeros((b, h, w))
    run_range(_errors, b * h, *arrays, near, float(clip), still, low, min_share=_MIN_ROWS)
    out = np.zeros((b, h, w), dtype=np.bool_)
    run_range(_rows, b * h, *arrays, mask, float(ratio), half, float(clip), still, low, out, min_share=_MIN_ROWS)
    return torch.from_numpy(out).view(b, 1, h, w)
