"""Three steps of a stream's change test as numba kernels: the distance to the nearest previous value
(:func:`~torch_depth_sr.stream.change.distances`' ``d1``), the depth votes
(:func:`~torch_depth_sr.stream.change.depth_votes`) and the dilation of a mask
(:func:`~torch_depth_sr.stream.matching.dilate`).

In torch each is a chain of whole-frame operations, each with a temporary: ``d1`` is 8 differences, 8 absolute values
and 8 minima over a padded copy, then a division and a selection; a dilation is a float copy of the mask and a
running maximum of ``2·radius`` shifted planes per axis. At 1376×1088 the two took about 0.1 s of a 2.6 s stream
step, the votes' 0/1 planes and their window means about 0.08 s more. Here each is one pass (the dilation and the
counts two: rows, then bands of columns). The same arithmetic: a difference, its absolute value, the smallest, one
division in the frame's dtype; a dilation is exact, and so is a window's count of 0/1 votes (the torch path's float64
sums of 0/1 values are those integers), from which the votes are formed with the torch path's roundings. So the results are the
torch path's bit for bit (tested). Rows and bands split across threads (:func:`~torch_depth_sr.native.run_range`).
Compiled by LLVM at first use and cached on disk (``cache=True``).
"""
from __future__ import annotations

import numpy as np
import torch
from numba import njit

from ..native import run_range

__all__ = ["dilate_cpu", "nearest_distance_cpu", "votes_cpu"]

_BAND = 64  # columns per task of the dilation's column pass
_MIN_ROWS = 16  # rows per task below which one thread does them


@njit(cache=True, nogil=True, error_model="numpy")
def _nearest(t0, t1, y, observed, previous, noise, per_pixel, out):
    """Rows ``[t0, t1)`` of the ``B·H`` rows: ``out`` = the smallest ``|y − previous_j|`` over the 3×3 neighbourhood
    (replicated at the border) over the noise, where ``observed > 0``; else 0."""
    h, w = y.shape[1], y.shape[2]
    for t in range(t0, t1):
        b = t // h
        i = t - b * h
        for j in range(w):
            if not observed[b, i, j] > 0:
                out[b, i, j] = 0
                continue
            v = y[b, i, j]
            best = abs(v - previous[b, i, j])
            for dy in range(-1, 2):
                ii = min(max(i + dy, 0), h - 1)
                for dx in range(-1, 2):
                    jj = min(max(j + dx, 0), w - 1)
                    d = abs(v - previous[b, ii, jj])
                    if d < best:
                        best = d
            out[b, i, j] = best / (noise[b, i, j] if per_pixel else noise[b, 0, 0])


def nearest_distance_cpu(y: torch.Tensor, observed: torch.Tensor, previous: torch.Tensor,
                         noise: torch.Tensor) -> torch.Tensor:
    """``distances(y, observed, previous, noise)[1]`` for (B,1,H,W) tensors of one float dtype on the CPU (``noise``
    (B,1,H,W) or (B,1,1,1)), no gradient."""
    b, _, h, w = y.shape
    arrays = [np.ascontiguousarray(t.detach().reshape(t.shape[0], t.shape[-2], t.shape[-1]).numpy())
              for t in (y, observed, previous, noise)]
    out = np.empty((b, h, w), dtype=arrays[0].dtype)
    run_range(_nearest, b * h, *arrays, noise.shape[-1] != 1 or noise.shape[-2] != 1, out, min_share=_MIN_ROWS)
    return torch.from_numpy(out).view(b, 1, h, w)


@njit(cache=True, nogil=True)
def _dilate_rows(t0, t1, mask, radius, out):
    """Rows ``[t0, t1)`` of the ``P·H`` rows of ``mask (P,H,W)`` uint8: ``out`` = 1 where a set pixel lies within
    ``radius`` columns (the row's window clipped to the image)."""
    h, w = mask.shape[1], mask.shape[2]
    count = np.empty(w + 1, dtype=np.int64)
    for t in range(t0, t1):
        p = t // h
        i = t - p * h
        count[0] = 0
        for j in range(w):
            count[j + 1] = count[j] + (1 if mask[p, i, j] else 0)
        for j in range(w):
            out[p, i, j] = 1 if count[min(w, j + radius + 1)] - count[max(0, j - radius)] > 0 else 0


@njit(cache=True, nogil=True)
def _dilate_columns(t0, t1, rows, radius, bands, out):
    """Tasks ``[t0, t1)`` of ``P·bands`` (plane, band of ``_BAND`` columns): the column pass of :func:`_dilate_rows`
    on its output."""
    h, w = rows.shape[1], rows.shape[2]
    count = np.empty((h + 1, _BAND), dtype=np.int64)
    for t in range(t0, t1):
        p = t // bands
        x0 = (t - p * bands) * _BAND
        x1 = min(w, x0 + _BAND)
        for x in range(x0, x1):
            count[0, x - x0] = 0
        for y in range(h):
            for x in range(x0, x1):
                count[y + 1, x - x0] = count[y, x - x0] + rows[p, y, x]
        for y in range(h):
            hi = min(h, y + radius + 1)
            lo = max(0, y - radius)
            for x in range(x0, x1):
                out[p, y, x] = count[hi, x - x0] - count[lo, x - x0] > 0


def dilate_cpu(mask: torch.Tensor, radius: int) -> torch.Tensor:
    """``dilate(mask, radius)`` of a (B,C,H,W) bool mask on the CPU: grown by a square of ``radius`` px."""
    b, ch, h, w = mask.shape
    a = np.ascontiguousarray(mask.reshape(b * ch, h, w).numpy()).view(np.uint8)
    rows = np.empty(a.shape, dtype=np.uint8)
    run_range(_dilate_rows, b * ch * h, a, int(radius), rows, min_share=_MIN_ROWS)
    out = np.empty(a.shape, dtype=np.bool_)
    bands = -(-w // _BAND)
    run_range(_dilate_columns, b * ch * bands, rows, int(radius), bands, out)
    return torch.from_numpy(out).view(b, ch, h, w)


@njit(cache=True, nogil=True)
def _vote_rows(t0, t1, d1, observed, threshold, radius, out):
    """Rows ``[t0, t1)`` of the ``B·H`` rows: per pixel the counts, over the row's window of ``radius`` columns each
    side (clipped to the image), of the measured pixels (``out[..., 1]``) and of those with ``d1 > threshold``
    (``out[..., 0]``)."""
    h, w = d1.shape[1], d1.shape[2]
    far = np.empty(w + 1, dtype=np.int32)
    seen = np.empty(w + 1, dtype=np.int32)
    for t in range(t0, t1):
        b = t // h
        i = t - b * h
        far[0] = 0
        seen[0] = 0
        for j in range(w):
            m = observed[b, i, j] > 0
            seen[j + 1] = seen[j] + (1 if m else 0)
            far[j + 1] = far[j] + (1 if m and d1[b, i, j] > threshold else 0)
        for j in range(w):
            hi = min(w, j + radius + 1)
            lo = max(0, j - radius)
            out[b, i, j, 0] = far[hi] - far[lo]
            out[b, i, j, 1] = seen[hi] - seen[lo]


@njit(cache=True, nogil=True, error_model="numpy")
def _vote_columns(t0, t1, rows, radius, bands, consts, out):
    """Tasks ``[t0, t1)`` of ``B·bands``: the column pass of :func:`_vote_rows` on its row counts, then the votes as
    ``depth_votes`` forms them in the frame's dtype: the counts' window means (float64, rounded once to the dtype),
    ``(num · n) / (den · n + prior)`` with ``consts = [n, prior, area]`` in the dtype."""
    h, w = rows.shape[1], rows.shape[2]
    count = np.empty((h + 1, _BAND, 2), dtype=np.int32)
    mean = np.empty(2, dtype=consts.dtype)  # a store rounds the float64 mean to the dtype, as .to(dtype) does
    area = np.float64(consts[2])
    for t in range(t0, t1):
        b = t // bands
        x0 = (t - b * bands) * _BAND
        x1 = min(w, x0 + _BAND)
        for x in range(x0, x1):
            count[0, x - x0, 0] = 0
            count[0, x - x0, 1] = 0
        for y in range(h):
            for x in range(x0, x1):
                count[y + 1, x - x0, 0] = count[y, x - x0, 0] + rows[b, y, x, 0]
                count[y + 1, x - x0, 1] = count[y, x - x0, 1] + rows[b, y, x, 1]
        for y in range(h):
            hi = min(h, y + radius + 1)
            lo = max(0, y - radius)
            for x in range(x0, x1):
                mean[0] = np.float64(count[hi, x - x0, 0] - count[lo, x - x0, 0]) / area
                mean[1] = np.float64(count[hi, x - x0, 1] - count[lo, x - x0, 1]) / area
                out[b, 0, y, x] = (mean[0] * consts[0]) / (mean[1] * consts[0] + consts[1])


def votes_cpu(d1: torch.Tensor, observed: torch.Tensor, threshold: float, window: int, prior: float) -> torch.Tensor:
    """``depth_votes(d1, observed, window, threshold)`` (B,1,H,W) for ``d1``, ``observed`` (B,1,H,W) of one float dtype:
    over the ``window × window`` window clipped to the image, the measured pixels with ``d1 > threshold`` against
    the measured pixels and ``prior`` pseudo-votes."""
    b, _, h, w = d1.shape
    a = np.ascontiguousarray(d1.detach().reshape(b, h, w).numpy())
    m = np.ascontiguousarray(observed.detach().reshape(b, h, w).numpy())
    rows = np.empty((b, h, w, 2), dtype=np.int32)
    radius = window // 2
    run_range(_vote_rows, b * h, a, m, a.dtype.type(threshold), radius, rows, min_share=_MIN_ROWS)
    out = np.empty((b, 1, h, w), dtype=a.dtype)
    bands = -(-w // _BAND)
    consts = np.array([window * window, prior, window * window], dtype=a.dtype)
    run_range(_vote_columns, b * bands, rows, radius, bands, consts, out)
    return torch.from_numpy(out)
