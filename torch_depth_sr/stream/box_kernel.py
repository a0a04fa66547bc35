"""The window means of a stream's change test and state (:func:`~torch_depth_sr.stream.change._box_mean`): a numba
kernel.

``_box_mean`` pads, takes float64 cumulative sums along rows, differences them, pads again, sums along columns and
differences again: eight passes over every plane with a temporary for each, memory-bound on large frames (at
1376×1088 the change test's and the state's window means took about a tenth of a stream step). This kernel makes the
same running sums in the same order (one float64 sum from the first padded element, as ``torch.cumsum``) and the same
differences and division, so the means are the same bit for bit (tested): a row pass writes each row's window sums,
a column pass, by bands of columns, the window means. Rows, and bands, split across threads
(:func:`~torch_depth_sr.native.run_range`) with the same results for any thread count.
The stream's noise units (:func:`~torch_depth_sr.stream.change.local_spread`,
:func:`~torch_depth_sr.stream.change.remembered_spread`) use the same passes on planes made on the fly (``|y − x|``
where measured, and the measured pixels), without the torch path's temporaries, and the same values; so does the
change test's drift test (:func:`~torch_depth_sr.stream.change.drifting`).
Compiled by LLVM at first use and cached on disk (``cache=True``).
"""
from __future__ import annotations

import numpy as np
import torch
from numba import njit

from ..native import run_range

__all__ = ["box_mean_cpu", "drift_cpu", "local_spread_cpu", "remembered_spread_cpu"]

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


def _window_means(row_pass, row_tasks: int, planes: int, h: int, w: int, window: int, *args) -> np.ndarray:
    """(planes, H, W) float64: the window means of planes whose row sums ``row_pass(t0, t1, *args, out)`` writes into
    ``out`` over ``row_tasks`` tasks (:func:`_rows` and the passes that make their planes on the fly), then the column
    pass (:func:`_columns`)."""
    rows = np.empty((planes, h, w), dtype=np.float64)
    run_range(row_pass, row_tasks, *args, rows, min_share=_MIN_ROWS)
    means = np.empty_like(rows)
    bands = -(-w // _BAND)
    run_range(_columns, planes * bands, rows, window, bands, means)
    return means


def box_mean_cpu(v: torch.Tensor, window: int) -> torch.Tensor:
    """``change._box_mean(v, window)`` of ``v (B,C,H,W)`` float32 or float64 on the CPU, no gradient."""
    b, ch, h, w = v.shape
    a = np.ascontiguousarray(v.detach().numpy().reshape(b * ch, h, w))
    means = _window_means(_rows, b * ch * h, b * ch, h, w, window, a, window)
    return torch.from_numpy(means).view(b, ch, h, w).to(v.dtype)


@njit(cache=True, nogil=True, error_model="numpy")
def _spread_rows(t0, t1, y, observed, x, past, window, consts, out):
    """Rows ``[t0, t1)`` of the ``B·P·H`` rows of :func:`_rows`' sums of the planes ``local_spread`` boxes, made on
    the fly (``P`` = the channels of ``x`` and ``past``, and one): plane ``c`` of a sample holds ``|y − x_c|`` where
    observed (else 0), then ``|y − past_c|``, then the measured pixels (1 or 0), each in the dtype first, as the
    torch path's planes of their concatenation."""
    nx, h, w = x.shape[1], x.shape[2], x.shape[3]
    per = nx + past.shape[1] + 1
    p = window // 2
    n = w + 2 * p + 1
    c = np.empty(n)
    one = consts[0]
    for t in range(t0, t1):
        plane = t // h
        i = t - plane * h
        b = plane // per
        ch = plane - b * per
        acc = 0.0
        for k in range(n):
            j = k - p - 1
            if 0 <= j < w and observed[b, 0, i, j] > 0:
                if ch < nx:
                    v = abs(y[b, 0, i, j] - x[b, ch, i, j])
                elif ch < per - 1:
                    v = abs(y[b, 0, i, j] - past[b, ch - nx, i, j])
                else:
                    v = one
                acc += np.float64(v)
            else:
                acc += 0.0
            c[k] = acc
        for j in range(w):
            out[plane, i, j] = c[j + window] - c[j]


@njit(cache=True, nogil=True, error_model="numpy")
def _spread_ratio(t0, t1, means, consts, out):
    """Rows ``[t0, t1)`` of the ``B·C·H`` rows: ``out`` = the mean of ``|y − x_c|`` over the mean of the measured
    pixels, each rounded to the dtype first (0 where no pixel of the window is measured)."""
    nc, h, w = out.shape[1], out.shape[2], out.shape[3]
    r = np.empty(2, dtype=out.dtype)  # a store rounds the float64 mean to the dtype, as .to(dtype) does
    for t in range(t0, t1):
        plane = t // h
        i = t - plane * h
        b = plane // nc
        ch = plane - b * nc
        for j in range(w):
            r[0] = means[b * (nc + 1) + ch, i, j]
            r[1] = means[b * (nc + 1) + nc, i, j]
            out[b, ch, i, j] = r[0] / max(r[1], consts[2]) if r[1] > 0 else consts[1]


def local_spread_cpu(y: torch.Tensor, observed: torch.Tensor, x: torch.Tensor, window: int) -> torch.Tensor:
    """``change.local_spread(y, observed, x, window)`` for ``y``, ``observed`` (B,1,H,W) and ``x`` (B,C,H,W) of one
    float dtype on the CPU, no gradient: the same window sums in the same order (:func:`_rows`, :func:`_columns`)
    of planes made on the fly, without the torch path's temporaries."""
    b, nc, h, w = x.shape
    arrays = [np.ascontiguousarray(t.detach().numpy()) for t in (y, observed, x)]
    dtype = arrays[0].dtype
    consts = np.array([1.0, 0.0, 1e-12], dtype=dtype)  # one, zero, the torch path's clamp of the measured share
    none = np.empty((b, 0, h, w), dtype=dtype)
    means = _window_means(_spread_rows, b * (nc + 1) * h, b * (nc + 1), h, w, window, *arrays, none, window, consts)
    out = np.empty((b, nc, h, w), dtype=dtype)
    run_range(_spread_ratio, b * nc * h, means, consts, out, min_share=_MIN_ROWS)
    return torch.from_numpy(out)


@njit(cache=True, nogil=True, error_model="numpy")
def _remember(t0, t1, means, past_spread, static, consts, out):
    """Rows ``[t0, t1)`` of the ``B·H`` rows: the spread about ``x`` and about ``past`` from the window means (as
    :func:`_spread_ratio`), then where ``static`` the larger of the spread and the remembered one: the larger of the
    spread about ``past`` and ``consts[3]`` times ``past_spread``."""
    h, w = out.shape[2], out.shape[3]
    r = np.empty(3, dtype=out.dtype)
    floor, zero, memory = consts[2], consts[1], consts[3]
    for t in range(t0, t1):
        b = t // h
        i = t - b * h
        for j in range(w):
            r[0] = means[3 * b, i, j]
            r[1] = means[3 * b + 1, i, j]
            r[2] = means[3 * b + 2, i, j]
            spread = r[0] / max(r[2], floor) if r[2] > 0 else zero
            if static[b, 0, i, j]:
                innovation = r[1] / max(r[2], floor) if r[2] > 0 else zero
                remembered = max(innovation, memory * past_spread[b, 0, i, j])
                spread = max(spread, remembered)
            out[b, 0, i, j] = spread


def remembered_spread_cpu(y: torch.Tensor, observed: torch.Tensor, x: torch.Tensor, past: torch.Tensor,
                          past_spread: torch.Tensor, static: torch.Tensor, window: int, memory: float) -> torch.Tensor:
    """``change.remembered_spread`` for (B,1,H,W) CPU tensors of one float dtype (``static`` bool), no gradient."""
    b, _, h, w = x.shape
    arrays = [np.ascontiguousarray(t.detach().numpy()) for t in (y, observed, x, past)]
    dtype = arrays[0].dtype
    consts = np.array([1.0, 0.0, 1e-12, memory], dtype=dtype)  # one, zero, the measured share's clamp, the memory
    means = _window_means(_spread_rows, b * 3 * h, b * 3, h, w, window, *arrays, window, consts)
    out = np.empty((b, 1, h, w), dtype=dtype)
    run_range(_remember, b * h, means, np.ascontiguousarray(past_spread.detach().numpy()),
              np.ascontiguousarray(static.detach().numpy()), consts, out, min_share=_MIN_ROWS)
    return torch.from_numpy(out)


@njit(cache=True, nogil=True, error_model="numpy")
def _drift_rows(t0, t1, y, observed, mean, has, noise, window, consts, out):
    """Rows ``[t0, t1)`` of the ``B·H`` rows: :func:`_rows`' sums of the two planes ``change.drifting`` boxes, made
    on the fly and summed side by side: sample ``b``'s plane ``2b`` holds ``clamp((y − mean) / noise, ±clip)`` where
    measured with a run (else 0), plane ``2b + 1`` those pixels (1 or 0), each value in the dtype first, as the torch
    path's."""
    h, w = y.shape[2], y.shape[3]
    p = window // 2
    n = w + 2 * p + 1
    c = np.empty((2, n))
    d = np.empty(1, dtype=y.dtype)  # a store rounds to the dtype, as each torch operation does
    one, clip = np.float64(consts[0]), consts[1]
    for t in range(t0, t1):
        b = t // h
        i = t - b * h
        acc = 0.0
        count = 0.0
        for k in range(n):
            j = k - p - 1
            if 0 <= j < w and observed[b, 0, i, j] > 0 and has[b, 0, i, j]:
                d[0] = y[b, 0, i, j] - mean[b, 0, i, j]
                d[0] = d[0] / noise[b, 0, i, j]
                d[0] = min(max(d[0], -clip), clip)
                acc += np.float64(d[0])
                count += one
            else:
                acc += 0.0
                count += 0.0
            c[0, k] = acc
            c[1, k] = count
        for j in range(w):
            out[2 * b, i, j] = c[0, j + window] - c[0, j]
            out[2 * b + 1, i, j] = c[1, j + window] - c[1, j]


@njit(cache=True, nogil=True, error_model="numpy")
def _drift_verdict(t0, t1, means, consts, out):
    """Rows ``[t0, t1)`` of the ``B·H`` rows: the window's sum and count from its means (each rounded to the dtype,
    then times the window's area in the dtype), and the verdict ``count ≥ 2.5 and |sum| > test · √count``."""
    h, w = out.shape[2], out.shape[3]
    r = np.empty(4, dtype=consts.dtype)
    area, least, test, zero = consts[2], consts[3], consts[4], consts[5]
    for t in range(t0, t1):
        b = t // h
        i = t - b * h
        for j in range(w):
            r[0] = means[2 * b, i, j]
            r[1] = means[2 * b + 1, i, j]
            r[2] = r[0] * area
            r[3] = r[1] * area
            out[b, 0, i, j] = r[3] >= least and abs(r[2]) > test * np.sqrt(max(r[3], zero))


def drift_cpu(y: torch.Tensor, observed: torch.Tensor, mean: torch.Tensor, has: torch.Tensor, noise: torch.Tensor,
              test: float, window: int, clip: float) -> torch.Tensor:
    """``change.drifting`` for (B,1,H,W) CPU tensors of one float dtype (``has`` bool), no gradient: the same window
    sums in the same order (:func:`_rows`' and :func:`_columns`' passes) of planes made on the fly."""
    b, _, h, w = y.shape
    arrays = [np.ascontiguousarray(t.detach().numpy()) for t in (y, observed, mean, has, noise)]
    dtype = arrays[0].dtype
    consts = np.array([1.0, clip, window * window, 2.5, test, 0.0], dtype=dtype)
    means = _window_means(_drift_rows, b * h, b * 2, h, w, window, *arrays, window, consts)
    out = np.empty((b, 1, h, w), dtype=np.bool_)
    run_range(_drift_verdict, b * h, means, consts, out, min_share=_MIN_ROWS)
    return torch.from_numpy(out)
