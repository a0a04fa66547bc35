"""The windowed weighted medians of the edge steps (``edge_snap.py``): numba kernels, one pixel at a time.

The torch path builds the whole ``(2 r + 1)²`` window of every pixel and sorts it (``sided_median``: every pixel;
``refit_to_measurements``: the pixels near a depth edge). These kernels keep only the window entries with a positive
weight (an offset outside the image, or whose mirror is outside, or an unmeasured or out-of-band measurement, weighs
0 and cannot be the median: the median is the first value whose cumulative weight reaches half the total) and sort
them (equal values in window order). No gradient: the torch path serves whenever autograd needs one.

Precision: the weights in the input dtype, as the torch path (``exp`` may differ from torch's by an ulp); the
cumulative weights summed in float64 and rounded to the input dtype, as torch's CPU ``cumsum``; the shares' sums in
float64. Medians agree with the torch path as values, except in rare ties at exactly half the total weight; shares to
the input dtype's round-off. With ``torch.get_num_threads() > 1`` equal shares of the pixels run in parallel
(:func:`~torch_depth_sr.native.run_range`), with one thread on the calling thread. Compiled by LLVM at first use
and cached on disk (``cache=True``).
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import torch
from numba import njit

from .native import as_numpy, run_range

__all__ = ["refit_cpu", "sided_median_cpu"]


@njit(cache=True, nogil=True)
def _sort(window_vals, window_wts, m, vals, wts):
    """The first ``m`` entries of ``window_vals, window_wts`` sorted by value into ``vals, wts``, equal values in
    window order: each entry goes to its rank, the count of the values below it and of the equal ones before it.
    The m² compares are a vector loop without branches; an insertion sort's shifts and mispredicted branches cost
    more at these window sizes (25 entries: a 320x240 frame's sided median 48-59 -> 41-45 ms, one thread). The
    values are finite (a NaN depth is a hole before any edge step): a NaN would share a rank with another value."""
    for q in range(m):
        v = window_vals[q]
        rank = 0
        for p in range(m):
            rank += (window_vals[p] < v) | ((window_vals[p] == v) & (p < q))
        vals[rank] = v
        wts[rank] = window_wts[q]


@njit(cache=True, nogil=True)
def _median(vals, wts, cum, m):
    """The index of the first of the ``m`` sorted entries whose cumulative weight (rounded to the dtype) reaches
    half the total, and the total (``-1`` and 0 when ``m == 0``)."""
    c = 0.0
    for k in range(m):
        c += wts[k]
        cum[k] = c  # rounded to the input dtype, as torch's cumsum
    if m == 0:
        return -1, 0.0
    half = 0.5 * cum[m - 1]
    for k in range(m):
        if not cum[k] < half:
            return k, cum[m - 1]
    return m - 1, cum[m - 1]


@njit(cache=True, nogil=True, inline="always")
def _colour_weight(g, gn, row, col, yy, xx, sigma):
    """``exp(−‖g(yy, xx) − g(row, col)‖₁ / sigma)`` over the channels of sample ``gn`` (``edge_snap._colour_weight``)."""
    dist = abs(g[gn, 0, yy, xx] - g[gn, 0, row, col])
    for c in range(1, g.shape[1]):
        dist += abs(g[gn, c, yy, xx] - g[gn, c, row, col])
    return np.exp(-dist / sigma)


@njit(cache=True, inline="always")
def _plane(r, dy, dx):
    """The plane of :func:`_colour_planes` that holds offset ``(dy, dx)`` (or its mirror ``(−dy, −dx)``)."""
    if dy < 0 or (dy == 0 and dx < 0):
        dy, dx = -dy, -dx
    return dx - 1 if dy == 0 else r + (dy - 1) * (2 * r + 1) + dx + r


@njit(cache=True, fastmath=False, nogil=True)
def _colour_planes(t0, t1, g, r, sigma, planes):
    """The colour weights :func:`_colour_weight` of rows ``[t0, t1)`` of the flattened (G, H) guide, for every
    offset of the half window (``dy > 0``, or ``dy = 0`` and ``dx > 0``): ``planes[n, _plane(r, dy, dx), i, j]``
    is the weight between pixels ``(i, j)`` and ``(i + dy, j + dx)`` where both lie in the image. The weight is
    symmetric, bit for bit (|a − b| = |b − a|), so the other half of the window reads the mirrored pixel's plane:
    half the exponentials, each a loop along a row."""
    _, nc, h, w = g.shape
    for t in range(t0, t1):
        n = t // h
        i = t - n * h
        for dy in range(0, r + 1):
            if i + dy >= h:
                break
            for dx in range(-r, r + 1):
                if dy == 0 and dx <= 0:
                    continue
                out = planes[n, _plane(r, dy, dx), i]
                j0 = max(0, -dx)
                j1 = min(w, w - dx)
                a = g[n, 0, i]
                q = g[n, 0, i + dy]
                for j in range(j0, j1):
                    out[j] = abs(q[j + dx] - a[j])
                for c in range(1, nc):
                    a = g[n, c, i]
                    q = g[n, c, i + dy]
                    for j in range(j0, j1):
                        out[j] += abs(q[j + dx] - a[j])
                for j in range(j0, j1):
                    out[j] = np.exp(-out[j] / sigma)


@njit(cache=True, fastmath=False, nogil=True)
def _sided(t0, t1, pixels, x, g, planes, spatial, r, sigma, cutoff, median, share):
    """``sided_median`` at pixels ``[t0, t1)`` of the flattened batch, or at ``pixels[t0:t1]`` (flat indices into
    (B, H, W)) when ``pixels`` is not empty: ``x`` (B, H, W), ``g`` (1 or B, C, H, W) and its colour weights
    ``planes`` (:func:`_colour_planes`; with no planes, ``(1, 0, 1, 1)``, the weights are computed as they are read)
    → ``median``, ``share`` (B, H, W). ``spatial`` holds a weight per window offset (``dy`` outer, ``dx`` inner), or
    nothing for a flat window.

    ``cutoff >= 0``: a pixel whose weight strictly below ``x_i`` and strictly above it are both at most ``cutoff``
    times the total is not sorted and reports ``(x_i, 0)``: its share (one of those two over the total) cannot exceed
    ``cutoff``, whichever side the median lies on. Sums in window order here, in sorted order for the share, so the
    caller leaves a margin of round-off between ``cutoff`` and the share it tests."""
    b, h, w = x.shape
    d = 2 * r + 1
    window_vals = np.empty(d * d, x.dtype)  # the window's voting entries in window order, then sorted
    window_wts = np.empty(d * d, x.dtype)
    vals = np.empty(d * d, x.dtype)
    wts = np.empty(d * d, x.dtype)
    cum = np.empty(d * d, x.dtype)
    tiny = np.finfo(x.dtype).tiny
    listed = pixels.shape[0] > 0
    direct = planes.shape[1] == 0  # no planes: each weight computed where it is read (a few listed pixels)
    for t in range(t0, t1):
        p = pixels[t] if listed else t
        n = p // (h * w)
        i = p - n * h * w
        row = i // w
        col = i - row * w
        gn = n if planes.shape[0] > 1 else 0
        xi = x[n, row, col]
        # the window offsets that vote: the offset and its mirror inside the image
        ry = min(r, row, h - 1 - row)
        rx = min(r, col, w - 1 - col)
        m = 0
        for dy in range(-ry, ry + 1):
            for dx in range(-rx, rx + 1):
                yy = row + dy
                xx = col + dx
                if direct or (dy == 0 and dx == 0):  # the centre: 1, or NaN for a NaN colour, as the torch path
                    wt = _colour_weight(g, gn, row, col, yy, xx, sigma)
                elif dy > 0 or (dy == 0 and dx > 0):
                    wt = planes[gn, _plane(r, dy, dx), row, col]
                else:
                    wt = planes[gn, _plane(r, dy, dx), yy, xx]
                if spatial.shape[0] > 0:
                    wt = wt * spatial[(dy + r) * d + dx + r]
                if wt > 0:
                    window_vals[m] = x[n, yy, xx]
                    window_wts[m] = wt
                    m += 1
        if cutoff >= 0.0:
            whole = 0.0
            below = 0.0
            above = 0.0
            for q in range(m):
                wq = np.float64(window_wts[q])
                whole += wq
                if window_vals[q] < xi:
                    below += wq
                elif window_vals[q] > xi:
                    above += wq
            if max(below, above) <= cutoff * whole:
                median[n, row, col] = xi
                share[n, row, col] = 0.0
                continue
        _sort(window_vals, window_wts, m, vals, wts)
        k, total = _median(vals, wts, cum, m)
        if k >= 0:
            med = vals[k]
        else:  # no weight (a NaN colour): the torch path's smallest value of the zero-padded window
            med = xi
            for dy in range(-r, r + 1):
                for dx in range(-r, r + 1):
                    yy = row + dy
                    xx = col + dx
                    v = x[n, yy, xx] if 0 <= yy < h and 0 <= xx < w else 0.0
                    med = min(med, v)
        side = 0.0
        for q in range(m):
            if (med < xi and vals[q] < xi) or (not med < xi and vals[q] > xi):
                side += wts[q]
        median[n, row, col] = med
        share[n, row, col] = side / max(total, tiny)


@njit(cache=True, fastmath=False, nogil=True)
def _refit(t0, t1, pixels, x, yz, obs, g, r, sigma, band, out):
    """``refit_to_measurements`` at ``pixels[t0:t1]`` (flat indices into (B, H, W)): ``x``, ``yz`` (measurements,
    0 where unobserved), ``obs`` (1 where observed) (B, H, W), ``g`` (1 or B, C, H, W) → ``out`` (B, H, W) at those
    pixels."""
    b, h, w = x.shape
    d = 2 * r + 1
    window_vals = np.empty(d * d, x.dtype)  # the window's voting entries in window order, then sorted
    window_wts = np.empty(d * d, x.dtype)
    vals = np.empty(d * d, x.dtype)
    wts = np.empty(d * d, x.dtype)
    cum = np.empty(d * d, x.dtype)
    for t in range(t0, t1):
        p = pixels[t]
        n = p // (h * w)
        i = p - n * h * w
        row = i // w
        col = i - row * w
        gn = n if g.shape[0] > 1 else 0
        xi = x[n, row, col]
        m = 0
        for yy in range(max(0, row - r), min(h, row + r + 1)):
            for xx in range(max(0, col - r), min(w, col + r + 1)):
                if not obs[n, yy, xx] > 0:
                    continue
                v = yz[n, yy, xx]
                if not abs(v - xi) <= band:
                    continue
                wt = _colour_weight(g, gn, row, col, yy, xx, sigma)
                if wt > 0:
                    window_vals[m] = v
                    window_wts[m] = wt
                    m += 1
        _sort(window_vals, window_wts, m, vals, wts)
        k, total = _median(vals, wts, cum, m)
        out[n, row, col] = vals[k] if k >= 0 and total > 1.0 else xi


def _np_dtype(x: torch.Tensor):
    return np.float64 if x.dtype == torch.float64 else np.float32


def sided_median_cpu(x: torch.Tensor, guide: torch.Tensor, radius: int, sigma_color: float,
                     spatial: Optional[torch.Tensor], cutoff: Optional[float] = None,
                     pixels: Optional[torch.Tensor] = None) -> tuple[torch.Tensor, torch.Tensor]:
    """``(median, share)``, each (B,1,H,W), of CPU float tensors ``x`` (B,1,H,W) and ``guide`` (1 or B, C, H, W),
    without gradient; ``spatial``: None or the ``(2 radius + 1)²`` offset weights in ``x``'s dtype. ``cutoff``: the
    pixels whose share cannot exceed it report ``(x_i, 0)`` unsorted (:func:`_sided`); None computes every pixel.
    ``pixels``: flat indices into (B, H, W), sorted; only those are computed, the others report ``(x_i, 0)``; their
    colour weights are computed where they are read, not as planes (the same weights but for the ulp by which a
    vectorised ``exp`` may differ)."""
    b, _, h, w = x.shape
    dt = _np_dtype(x)
    xn = as_numpy(x, (b, h, w), dt)
    gn = as_numpy(guide.to(x.dtype), guide.shape, dt)
    sp = as_numpy(spatial, (-1,), dt) if spatial is not None else np.zeros(0, dt)
    if pixels is None:
        median = np.empty((b, h, w), dt)
        share = np.empty((b, h, w), dt)
        listed = np.zeros(0, np.int64)
    else:
        median = xn.copy()
        share = np.zeros((b, h, w), dt)
        listed = as_numpy(pixels, (-1,), np.int64)
    r = int(radius)
    # one guide's weight planes at a time (2r(r+1) planes of H×W: 72 MB at 1376×1088, r = 2), whatever the batch;
    # none for listed pixels (near depth edges, a few percent): there each weight is computed where it is read
    planes = np.empty((1, 2 * r * (r + 1), h, w), dt) if pixels is None else np.empty((1, 0, 1, 1), dt)
    samples = [slice(0, b)] if gn.shape[0] == 1 else [slice(n, n + 1) for n in range(b)]
    for rows in samples:
        g = gn if gn.shape[0] == 1 else gn[rows]
        if listed.shape[0]:  # this sample's listed pixels, as flat indices into its own (1, H, W)
            lo, hi = np.searchsorted(listed, [rows.start * h * w, rows.stop * h * w])
            if lo == hi:
                continue
            todo, count = listed[lo:hi] - rows.start * h * w, hi - lo
        elif pixels is not None:  # an empty list: nothing to compute
            break
        else:
            todo, count = listed, (rows.stop - rows.start) * h * w
        if pixels is None:
            run_range(_colour_planes, h, g, r, dt(sigma_color), planes)
        run_range(_sided, count, todo, xn[rows], g, planes, sp, r, dt(sigma_color),
                  -1.0 if cutoff is None else float(cutoff), median[rows], share[rows])
    return torch.from_numpy(median).view(b, 1, h, w), torch.from_numpy(share).view(b, 1, h, w)


def refit_cpu(x: torch.Tensor, y: torch.Tensor, observed: torch.Tensor, guide: torch.Tensor, pixels: torch.Tensor,
              radius: int, band: float, sigma_color: float) -> torch.Tensor:
    """``x`` with the refitted values at ``pixels`` (flat indices into (B, H, W)), of CPU float tensors: ``x``, ``y``,
    ``observed`` (B,1,H,W) (``y`` and ``observed`` may broadcast), ``guide`` (1 or B, C, H, W). No gradient."""
    b, _, h, w = x.shape
    dt = _np_dtype(x)
    xn = as_numpy(x, (b, h, w), dt)
    seen = (observed > 0).expand(b, 1, h, w)
    yz = as_numpy(torch.where(seen, y.to(x.dtype), torch.zeros((), dtype=x.dtype)), (b, h, w), dt)
    on = as_numpy(seen.to(x.dtype), (b, h, w), dt)
    gn = as_numpy(guide.to(x.dtype), guide.shape, dt)
    out = xn.copy()
    pn = as_numpy(pixels, (-1,), np.int64)
    run_range(_refit, pn.shape[0], pn, xn, yz, on, gn, int(radius), dt(sigma_color), dt(band), out)
    return torch.from_numpy(out).view(b, 1, h, w)
