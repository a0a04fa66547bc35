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

__all__ = ["nonlocal_terms_cpu"]


@njit(cache=True, fastmath=False, nogil=True)
def _pixels(t0, t1, x, g, idx, wt, width, ridge, range_sigma, alpha, stats):
    """α and the statistics of pixels ``[t0, t1)`` of the flattened batch.

    ``x`` (B, HW), ``g`` (B, 2, HW), ``idx``/``wt`` (B, k, HW) → ``alpha`` (B, 2, HW), ``stats`` (B, 3, HW):
    x̄, the weighted variance and the squared centroid offset. With ``ridge > 0`` x̄ is the value at the pixel
    of the plane fitted to the matched centres (weighted least squares, ridge on the slope) and the variance
    that of the residuals (see ``nonlocal_prior.nonlocal_terms``). ``g`` and ``alpha`` have 0 channels when α is
    not wanted.
    """
    k = idx.shape[1]
    hw = idx.shape[2]
    with_alpha = g.shape[1] == 2
    xm = np.empty(k)  # the pixel's matched values, offsets and weights, read once
    dym = np.empty(k)
    dxm = np.empty(k)
    wm = np.empty(k)
    for t in range(t0, t1):
        n = t // hw
        i = t - n * hw
        row = i // width
        col = i - row * width
        sw = 0.0
        xb = 0.0
        oy = 0.0
        ox = 0.0
        xi = x[n, i]
        rs = range_sigma[n, i] if range_sigma.shape[1] > 0 else 0.0
        for m in range(k):
            j = idx[n, m, i]
            wm[m] = wt[n, m, i]
            xm[m] = x[n, j]
            if rs > 0.0:
                r = (xm[m] - xi) / rs
                wm[m] *= np.exp(-0.5 * r * r)
            jr = j // width
            dym[m] = jr - row
            dxm[m] = j - jr * width - col
            sw += wm[m]
            xb += wm[m] * xm[m]
            oy += wm[m] * dym[m]
            ox += wm[m] * dxm[m]
        if sw > 0.0:
            xb /= sw
            oy /= sw
            ox /= sw
        var = 0.0
        syy = 0.0
        sxx = 0.0
        syx = 0.0
        syv = 0.0
        sxv = 0.0
        for m in range(k):
            d = xm[m] - xb
            ey = dym[m] - oy
            ex = dxm[m] - ox
            var += wm[m] * d * d
            syy += wm[m] * ey * ey
            sxx += wm[m] * ex * ex
            syx += wm[m] * ey * ex
            syv += wm[m] * ey * d
            sxv += wm[m] * ex * d
        if sw > 0.0:
            var /= sw
            syy /= sw
            sxx /= sw
            syx /= sw
            syv /= sw
            sxv /= sw
        if ridge > 0.0:
            a11 = syy + ridge
            a22 = sxx + ridge
            det = a11 * a22 - syx * syx
            gy = (a22 * syv - syx * sxv) / det
            gx = (a11 * sxv - syx * syv) / det
            res = var - 2.0 * (gy * syv + gx * sxv) + gy * gy * syy + 2.0 * gy * gx * syx + gx * gx * sxx
            xb = xb - (gy * oy + gx * ox)
            var = res if res > 0.0 else 0.0
        if sw <= 1e-12:  # no centre left (range weights): no estimate, never passes the variance gate
            var = np.inf
        stats[n, 0, i] = xb
        stats[n, 1, i] = var
        stats[n, 2, i] = oy * oy + ox * ox
        if with_alpha:
            a0 = 0.0
            a1 = 0.0
            for m in range(k):
                j = idx[n, m, i]
                a0 += wt[n, m, i] * g[n, 0, j]
                a1 += wt[n, m, i] * g[n, 1, j]
            alpha[n, 0, i] = a0
            alpha[n, 1, i] = a1


def nonlocal_terms_cpu(x: torch.Tensor, grad_x: Optional[torch.Tensor], index: torch.Tensor, weight: torch.Tensor,
                       ridge: float = 0.0, range_sigma: Optional[torch.Tensor] = None
                       ) -> tuple[Optional[torch.Tensor], torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(α or None, x̄, variance, squared centroid offset)`` of CPU float tensors, without gradient.

    Args:
        x: ``(B,1,H,W)`` float32/64. ``grad_x``: ``(B,2,H,W)`` ``D x``, or None (no α).
        index, weight: ``(B,k,H,W)`` matches and their weights.
        ridge: > 0 fits a plane to the matched centres (see :func:`_pixels`); 0 takes their weighted mean.
        range_sigma: None, or a ``(B,1,H,W)`` map (or broadcastable) of the range σ that also weighs each centre
            of the value prior by exp(−(x_j − x_i)²/2σ²) (0 = not there).

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
    alpha = np.empty((b, gn.shape[1], h * w), dtype=np_dt)
    stats = np.empty((b, 3, h * w), dtype=np_dt)
    # one equal share of the pixels per thread (_pixels releases the GIL; few hand-offs), or on the calling thread
    run_range(_pixels, b * h * w, xn, gn, idxn, wn, w, float(ridge), rsn, alpha, stats)
    st = torch.from_numpy(stats).view(b, 3, h, w)
    a = torch.from_numpy(alpha).view(b, 2, h, w) if grad_x is not None else None
    return a, st[:, 0:1], st[:, 1:2], st[:, 2:3]
