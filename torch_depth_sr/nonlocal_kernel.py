"""The nonlocal terms of one layer (``nonlocal_prior.py``) in one pass over the matches: a numba kernel.

For every pixel it reads the ``k`` matched centres once and returns the nonlocal gradient
``α = Σ ω D x_j`` and the value prior's statistics ``x̄ = Σ ω x_j``, the weighted variance of the ``x_j``
and the squared length of the weighted centroid offset. The torch path needs a ``(B, 3, k, H, W)``
gather and ~15 passes over it. No gradient: the torch path serves whenever autograd needs one.

Sums are in float64 (the torch path sums in the input dtype); the outputs agree with the torch path to
the input dtype's round-off. With ``torch.get_num_threads() > 1`` shares of the pixels run in parallel (the kernel
releases the GIL; :func:`~torch_depth_sr.native.run_range`, not ``numba.prange``, which compiles several times
longer), with one thread the loop runs on the calling thread.
Compiled by LLVM at first use and cached on disk (``cache=True``).
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import torch
from numba import njit

from .native import as_numpy, run_range

__all__ = ["nonlocal_gradient_cpu", "nonlocal_terms_cpu"]


_CHUNK = 256  # pixels per chunk: the chunk's (k, chunk) scratch stays in a core's L1/L2 cache


@njit(cache=True, fastmath=False, nogil=True)
def _pixels(t0, t1, x, g, idx, wt, width, ridge, range_sigma, region, alpha, stats):
    """α and the statistics of pixels ``[t0, t1)`` of the flattened batch.

    ``x`` (B, HW), ``g`` (B, 2, HW), ``idx``/``wt`` (B, k, HW) → ``alpha`` (B, 2, HW), ``stats`` (B, 3, HW):
    x̄, the weighted variance and the squared centroid offset. With ``ridge > 0`` x̄ is the value at the pixel
    of the plane fitted to the matched centres (weighted least squares, ridge on the slope) and the variance
    that of the residuals (see ``nonlocal_prior.nonlocal_terms``). ``g`` and ``alpha`` have 0 channels when α is
    not wanted. ``region`` (B, HW) uint8: only its pixels are computed (the others' outputs are left as they are);
    0 columns: every pixel.

    The pixels go in chunks, each statistic a loop over the chunk's pixels inside a loop over the k matches,
    without branches, so that LLVM runs it on vectors of pixels; every pixel's sums are taken in the order of
    its matches, as one pixel at a time would (the same values). Rows and columns come from flat indices by
    float64 floor, exact for any index below 2^40. The chunk's arrays are views that start at 0 and the gathers
    index by unsigned ints: numba wraps a negative signed index around, a test on every access that LLVM drops
    only where it can tell the index is not negative.
    """
    k = idx.shape[1]
    hw = idx.shape[2]
    with_alpha = g.shape[1] == 2
    with_range = range_sigma.shape[1] > 0
    with_region = region.shape[1] > 0
    inv_w = 1.0 / width
    size = _CHUNK
    xm = np.empty((k, size))  # the chunk's matched values, offsets and weights, read once
    dym = np.empty((k, size))
    dxm = np.empty((k, size))
    wm = np.empty((k, size))
    acc = np.empty((10, size))  # Σω, x̄, ōy, ōx, then the second moments
    rows = np.empty(size)  # the chunk's pixels' rows and columns
    cols = np.empty(size)
    t = t0
    while t < t1:
        n = t // hw
        i0 = t - n * hw
        c = min(size, t1 - t, hw - i0)
        if with_region:  # the run of region pixels that starts here, or the next pixel
            if region[n, i0] == 0:
                t += 1
                continue
            run = 1
            while run < c and region[n, i0 + run] != 0:
                run += 1
            c = run
        xn = x[n]
        xc = xn[i0:i0 + c]
        rsn = range_sigma[n, i0:i0 + c] if with_range else xc
        for a in range(acc.shape[0]):
            for u in range(c):
                acc[a, u] = 0.0
        sw, xb, oy, ox = acc[0], acc[1], acc[2], acc[3]
        for u in range(c):
            rows[u] = np.floor((i0 + u + 0.5) * inv_w)
            cols[u] = (i0 + u) - rows[u] * width
        for m in range(k):
            im = idx[n, m, i0:i0 + c]
            wr = wt[n, m, i0:i0 + c]
            xr, yr, dr, wmr = xm[m], dym[m], dxm[m], wm[m]
            for u in range(c):
                j = im[u]
                xr[u] = xn[np.uint64(j)]
                jr = np.floor((j + 0.5) * inv_w)
                yr[u] = jr - rows[u]
                dr[u] = (j - jr * width) - cols[u]
            if with_range:
                for u in range(c):
                    rs = np.float64(rsn[u])
                    r = (xr[u] - xc[u]) / (rs if rs > 0.0 else 1.0)
                    wmr[u] = wr[u] * np.exp(-0.5 * r * r) if rs > 0.0 else wr[u]
            else:
                for u in range(c):
                    wmr[u] = wr[u]
            for u in range(c):
                w = wmr[u]
                sw[u] += w
                xb[u] += w * xr[u]
                oy[u] += w * yr[u]
                ox[u] += w * dr[u]
        for u in range(c):
            s = sw[u] if sw[u] > 0.0 else 1.0
            xb[u] = xb[u] / s
            oy[u] = oy[u] / s
            ox[u] = ox[u] / s
        var, syy, sxx, syx, syv, sxv = acc[4], acc[5], acc[6], acc[7], acc[8], acc[9]
        for m in range(k):
            xr, yr, dr, wmr = xm[m], dym[m], dxm[m], wm[m]
            for u in range(c):
                w = wmr[u]
                d = xr[u] - xb[u]
                ey = yr[u] - oy[u]
                ex = dr[u] - ox[u]
                var[u] += w * d * d
                syy[u] += w * ey * ey
                sxx[u] += w * ex * ex
                syx[u] += w * ey * ex
                syv[u] += w * ey * d
                sxv[u] += w * ex * d
        s0, s1, s2 = stats[n, 0, i0:i0 + c], stats[n, 1, i0:i0 + c], stats[n, 2, i0:i0 + c]
        for u in range(c):
            s = sw[u] if sw[u] > 0.0 else 1.0
            v = var[u] / s
            a_yy = syy[u] / s
            a_xx = sxx[u] / s
            a_yx = syx[u] / s
            a_yv = syv[u] / s
            a_xv = sxv[u] / s
            xbu = xb[u]
            if ridge > 0.0:
                a11 = a_yy + ridge
                a22 = a_xx + ridge
                det = a11 * a22 - a_yx * a_yx
                gy = (a22 * a_yv - a_yx * a_xv) / det
                gx = (a11 * a_xv - a_yx * a_yv) / det
                res = v - 2.0 * (gy * a_yv + gx * a_xv) + gy * gy * a_yy + 2.0 * gy * gx * a_yx + gx * gx * a_xx
                xbu = xbu - (gy * oy[u] + gx * ox[u])
                v = res if res > 0.0 else 0.0
            # no centre left (range weights): no estimate, never passes the variance gate
            s0[u] = xbu
            s1[u] = np.inf if sw[u] <= 1e-12 else v
            s2[u] = oy[u] * oy[u] + ox[u] * ox[u]
        if with_alpha:
            a0, a1 = acc[0], acc[1]  # Σω and x̄ are written out: reuse their rows
            for u in range(c):
                a0[u] = 0.0
                a1[u] = 0.0
            g0, g1 = g[n, 0], g[n, 1]
            for m in range(k):
                im = idx[n, m, i0:i0 + c]
                wr = wt[n, m, i0:i0 + c]
                for u in range(c):
                    j = np.uint64(im[u])
                    w = wr[u]
                    a0[u] += w * g0[j]
                    a1[u] += w * g1[j]
            al0 = alpha[n, 0, i0:i0 + c]
            al1 = alpha[n, 1, i0:i0 + c]
            for u in range(c):
                al0[u] = a0[u]
                al1[u] = a1[u]
        t += c


def nonlocal_terms_cpu(x: torch.Tensor, grad_x: Optional[torch.Tensor], index: torch.Tensor, weight: torch.Tensor,
                       ridge: float = 0.0, range_sigma: Optional[torch.Tensor] = None,
                       region: Optional[torch.Tensor] = None
                       ) -> tuple[Optional[torch.Tensor], torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(α or None, x̄, variance, squared centroid offset)`` of CPU float tensors, without gradient.

    Args:
        x: ``(B,1,H,W)`` float32/64. ``grad_x``: ``(B,2,H,W)`` ``D x``, or None (no α).
        index, weight: ``(B,k,H,W)`` matches and their weights.
        ridge: > 0 fits a plane to the matched centres (see :func:`_pixels`); 0 takes their weighted mean.
        range_sigma: None, or a ``(B,1,H,W)`` map (or broadcastable) of the range σ that also weighs each centre
            of the value prior by exp(−(x_j − x_i)²/2σ²) (0 = not there).
        region: None, or a ``(B,1,H,W)`` bool map: the outputs are computed at its pixels only, 0 elsewhere.

    Returns:
        α ``(B,2,H,W)`` (None without ``grad_x``), then x̄, variance, offset², each ``(B,1,H,W)``, in ``x``'s dtype.
    """
    b, _, h, w = x.shape
    k = index.shape[1]
    np_dt = np.float64 if x.dtype == torch.float64 else np.float32
    xn = as_numpy(x, (b, h * w), np_dt)
    gn = as_numpy(grad_x.to(x.dtype), (b, 2, h * w), np_dt) if grad_x is not None else np.zeros((b, 0, h * w), np_dt)
    idxn = as_numpy(index.to(torch.int64), (b, k, h * w), np.int64)
    wn = as_numpy(weight.to(x.dtype), (b, k, h * w), np_dt)
    # per-pixel range σ of the value prior's centre weights (0 = none), or no channel at all
    rsn = (as_numpy(range_sigma.to(x.dtype).expand(b, 1, h, w), (b, h * w), np_dt) if range_sigma is not None
           else np.zeros((b, 0), np_dt))
    if region is None:
        reg, shares, alloc = np.zeros((b, 0), np.uint8), 1, np.empty
    else:  # a region's pixels lie where the scene changed, not spread evenly: more shares balance the threads
        reg, shares, alloc = as_numpy(region, (b, h * w), np.uint8), 8, np.zeros
    alpha = alloc((b, gn.shape[1], h * w), dtype=np_dt)
    stats = alloc((b, 3, h * w), dtype=np_dt)
    # one equal share of the pixels per thread (_pixels releases the GIL; few hand-offs), or on the calling thread
    run_range(_pixels, b * h * w, xn, gn, idxn, wn, w, float(ridge), rsn, reg, alpha, stats, shares=shares)
    st = torch.from_numpy(stats).view(b, 3, h, w)
    a = torch.from_numpy(alpha).view(b, 2, h, w) if grad_x is not None else None
    return a, st[:, 0:1], st[:, 1:2], st[:, 2:3]


@njit(cache=True, nogil=True, error_model="numpy")
def _gradient(t0, t1, g, idx, wt, alpha):
    """α alone at pixels ``[t0, t1)`` of the flattened batch, with :func:`_pixels`' arithmetic (each product in the
    input dtype, summed in float64 in the order of the matches, one rounding at the store): the same values."""
    k = idx.shape[1]
    hw = idx.shape[2]
    for t in range(t0, t1):
        n = t // hw
        i = t - n * hw
        a0 = 0.0
        a1 = 0.0
        for m in range(k):
            j = np.uint64(idx[n, m, i])
            w = wt[n, m, i]
            a0 += w * g[n, 0, j]
            a1 += w * g[n, 1, j]
        alpha[n, 0, i] = a0
        alpha[n, 1, i] = a1


def nonlocal_gradient_cpu(grad_x: torch.Tensor, index: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """α (B,2,H,W): :func:`nonlocal_terms_cpu`'s α alone, the same values without the value statistics (x⁰'s α⁰
    needs none: a third of the work), for CPU float ``grad_x`` (B,2,H,W) and the matches, without gradient."""
    b, _, h, w = grad_x.shape
    k = index.shape[1]
    np_dt = np.float64 if grad_x.dtype == torch.float64 else np.float32
    gn = as_numpy(grad_x, (b, 2, h * w), np_dt)
    idxn = as_numpy(index.to(torch.int64), (b, k, h * w), np.int64)
    wn = as_numpy(weight.to(grad_x.dtype), (b, k, h * w), np_dt)
    alpha = np.empty((b, 2, h * w), dtype=np_dt)
    run_range(_gradient, b * h * w, gn, idxn, wn, alpha)
    return torch.from_numpy(alpha).view(b, 2, h, w)
