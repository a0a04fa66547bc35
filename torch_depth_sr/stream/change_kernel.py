"""The steps of a stream's change test as numba kernels: the distance to the nearest previous value
(:func:`~torch_depth_sr.stream.change.distances`' ``d1``), the depth votes
(:func:`~torch_depth_sr.stream.change.depth_votes`), the colour change
(:func:`~torch_depth_sr.stream.change.colour_changes`) and the camera test's shifted differences
(:func:`~torch_depth_sr.stream.change.camera_moved`).

In torch each is a chain of whole-frame operations, each with a temporary: ``d1`` is 8 differences, 8 absolute values
and 8 minima over a padded copy, then a division and a selection. At 1376×1088 it and the mask dilations took about
0.1 s of a 2.6 s stream step, the votes' 0/1 planes and their window means about 0.08 s more. Here ``d1`` is one pass.
The votes are formed from the window counts of the far and the measured pixels (:func:`_window_counts`: a row pass,
then bands of columns) with the torch path's roundings (the torch path's float64 window sums of 0/1 values are those
integers). The colour change and each pixel's own change are one pass over the channels. The same
arithmetic as torch throughout (a difference, its absolute value, the smallest, one division in the frame's dtype),
so the results are the torch path's bit for bit (tested) — except the camera test's 25 sums, taken in float64 and
reassociated (vectorised): they agree with torch's float32 means to float32 rounding. Rows and bands split across
threads (:func:`~torch_depth_sr.native.run_range`). Compiled by LLVM at first use and cached on disk (``cache=True``).
"""
from __future__ import annotations

import numpy as np
import torch
from numba import njit

from ..native import run_range

__all__ = ["colour_change_cpu", "nearest_distance_cpu", "shift_changes_cpu", "votes_cpu"]

_BAND = 64  # columns per task of the window counts' column pass
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
def _count_rows(t0, t1, planes, radius, out):
    """Rows ``[t0, t1)`` of the ``P·H`` rows of ``planes (P,H,W)`` uint8: ``out`` (int32) = the set pixels within
    ``radius`` columns (the row's window clipped to the image)."""
    h, w = planes.shape[1], planes.shape[2]
    count = np.empty(w + 1, dtype=np.int32)
    for t in range(t0, t1):
        p = t // h
        i = t - p * h
        count[0] = 0
        for j in range(w):
            count[j + 1] = count[j] + (1 if planes[p, i, j] else 0)
        for j in range(w):
            out[p, i, j] = count[min(w, j + radius + 1)] - count[max(0, j - radius)]


@njit(cache=True, nogil=True)
def _count_columns(t0, t1, rows, radius, bands, out):
    """Tasks ``[t0, t1)`` of ``P·bands`` (plane, band of ``_BAND`` columns): the column pass of :func:`_count_rows`
    on its row counts: the window counts."""
    h, w = rows.shape[1], rows.shape[2]
    count = np.empty((h + 1, _BAND), dtype=np.int32)
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
                out[p, y, x] = count[hi, x - x0] - count[lo, x - x0]


def _window_counts(planes: torch.Tensor, radius: int) -> np.ndarray:
    """(P,H,W) int32: the set pixels of each of the bool ``planes`` (..., H, W) within ``radius`` px of each pixel
    (a square clipped to the image): what a box filter with zero padding sums over a 0/1 plane."""
    h, w = planes.shape[-2:]
    a = np.ascontiguousarray(planes.reshape(-1, h, w).numpy()).view(np.uint8)
    rows = np.empty(a.shape, dtype=np.int32)
    run_range(_count_rows, a.shape[0] * h, a, int(radius), rows, min_share=_MIN_ROWS)
    out = np.empty(a.shape, dtype=np.int32)
    bands = -(-w // _BAND)
    run_range(_count_columns, a.shape[0] * bands, rows, int(radius), bands, out)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _votes(t0, t1, counts, consts, out):
    """Rows ``[t0, t1)`` of the ``B·H`` rows: the votes as ``depth_votes`` forms them in the frame's dtype from the
    window counts ``counts (2B, H, W)`` (the far votes of sample b in plane b, its measured pixels in plane B + b):
    their window means (float64, rounded once to the dtype), ``(num · n) / (den · n + prior)`` with ``consts = [n,
    prior, area]`` in the dtype."""
    half, h, w = counts.shape[0] // 2, counts.shape[1], counts.shape[2]
    mean = np.empty(2, dtype=consts.dtype)  # a store rounds the float64 mean to the dtype, as .to(dtype) does
    area = np.float64(consts[2])
    for t in range(t0, t1):
        b = t // h
        i = t - b * h
        for j in range(w):
            mean[0] = np.float64(counts[b, i, j]) / area
            mean[1] = np.float64(counts[half + b, i, j]) / area
            out[b, i, j] = (mean[0] * consts[0]) / (mean[1] * consts[0] + consts[1])


def votes_cpu(d1: torch.Tensor, observed: torch.Tensor, threshold: float, window: int, prior: float) -> torch.Tensor:
    """``depth_votes(d1, observed, window, threshold)`` (B,1,H,W) for ``d1``, ``observed`` (B,1,H,W) of one float dtype:
    over the ``window × window`` window clipped to the image, the measured pixels with ``d1 > threshold`` against
    the measured pixels and ``prior`` pseudo-votes."""
    b, _, h, w = d1.shape
    measured = observed > 0
    counts = _window_counts(torch.cat([(d1 > threshold) & measured, measured]), window // 2)  # (2B, H, W)
    dtype = d1.detach().numpy().dtype
    out = np.empty((b, h, w), dtype=dtype)
    consts = np.array([window * window, prior, window * window], dtype=dtype)
    run_range(_votes, b * h, counts, consts, out, min_share=_MIN_ROWS)
    return torch.from_numpy(out).view(b, 1, h, w)


@njit(cache=True, nogil=True, error_model="numpy")
def _colour(t0, t1, diff, median, consts, change, own):
    """Rows ``[t0, t1)`` of the ``B·H`` rows: ``change`` = the mean over the channels of ``|diff − median|`` (each
    channel's median change removed), ``own`` = the mean of ``|diff|`` above ``consts[1]``; ``consts = [channels,
    test]`` in the dtype. The channels summed in order, then divided: torch's ``abs().mean(1)``."""
    h, w, nc = diff.shape[2], diff.shape[3], diff.shape[1]
    n, test = consts[0], consts[1]
    for t in range(t0, t1):
        b = t // h
        i = t - b * h
        for j in range(w):
            d = diff[b, 0, i, j]
            s = abs(d - median[b, 0])
            r = abs(d)
            for c in range(1, nc):
                d = diff[b, c, i, j]
                s += abs(d - median[b, c])
                r += abs(d)
            change[b, i, j] = s / n
            own[b, i, j] = r / n > test


def colour_change_cpu(diff: torch.Tensor, median: torch.Tensor, test: float) -> tuple[torch.Tensor, torch.Tensor]:
    """``((diff − median).abs().mean(1, keepdim=True), diff.abs().mean(1, keepdim=True) > test)`` for ``diff``
    (B,C,H,W) and ``median`` (B,C) of one float dtype on the CPU, no gradient."""
    b, nc, h, w = diff.shape
    d = np.ascontiguousarray(diff.detach().numpy())
    m = np.ascontiguousarray(median.detach().reshape(b, nc).numpy(), dtype=d.dtype)
    change = np.empty((b, h, w), dtype=d.dtype)
    own = np.empty((b, h, w), dtype=np.bool_)
    run_range(_colour, b * h, d, m, np.array([nc, test], dtype=d.dtype), change, own, min_share=_MIN_ROWS)
    return torch.from_numpy(change).view(b, 1, h, w), torch.from_numpy(own).view(b, 1, h, w)


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc"})
def _shifts(t0, t1, a, b, centre, reach, out):
    """Rows ``[t0, t1)`` of the ``B·(H − 2·reach)`` rows of the core: ``out[t, s]`` = the row's sum (float64) of
    ``|(a − centre_a) − (b_shifted − centre_b)|`` for each shift ``s`` of ``(dy, dx)`` in ``[-reach, reach]²``
    (row-major). The sums may be reassociated (vectorised): not bit for bit any fixed order."""
    h, w = a.shape[1], a.shape[2]
    rows = h - 2 * reach
    side = 2 * reach + 1
    for t in range(t0, t1):
        n = t // rows
        i = t - n * rows + reach
        offset = centre[n, 1] - centre[n, 0]  # b's centre minus a's
        core = w - 2 * reach
        ar = a[n, i, reach:w - reach]
        for s in range(side * side):
            dy = s // side - reach
            dx = s - (s // side) * side - reach
            br = b[n, i + dy, reach + dx:reach + dx + core]
            acc = 0.0
            for j in range(core):
                acc += abs(np.float64(ar[j]) - np.float64(br[j]) + offset)
            out[t, s] = acc


def shift_changes_cpu(a: torch.Tensor, b: torch.Tensor, reach: int) -> torch.Tensor:
    """(B, (2·reach + 1)²) float64: ``camera_moved``'s mean absolute changes of the centred images ``a``, ``b``
    (B,H,W; H, W > 2·reach) over the core, for each shift of ``b``, row-major from (−reach, −reach). One pass over the
    core rows with the sums in float64 (torch's float32 means differ from them in the last bits)."""
    n, h, w = a.shape
    x = np.ascontiguousarray(a.detach().numpy())
    y = np.ascontiguousarray(b.detach().numpy(), dtype=x.dtype)
    centre = np.stack([x.reshape(n, -1).mean(1, dtype=np.float64), y.reshape(n, -1).mean(1, dtype=np.float64)], 1)
    rows = h - 2 * reach
    out = np.empty((n * rows, (2 * reach + 1) ** 2))
    run_range(_shifts, n * rows, x, y, centre, reach, out, min_share=_MIN_ROWS)
    count = rows * (w - 2 * reach)
    return torch.from_numpy(out.reshape(n, rows, -1).sum(1) / count)
