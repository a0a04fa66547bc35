"""The rounds of the singular-pixel test (``singular.py``) with a numba kernel for the CPU.

The torch path makes ~30 passes over ``(B, k, H, W)`` tensors per round; this kernel reads the ``k``
matches of a pixel once per round. The rounds are Jacobi-style (round
``r`` reads the ``Q`` of round ``r − 1`` only), so the result does not depend on the thread count. Two
shortcuts change no result: after the first round only pixels with a matched centre whose ``Q`` changed
in the previous round are recomputed (the others' statistics are unchanged), and a round in which no
``Q`` changed ends the test. On the CPU neither costs a host synchronisation.

With ``torch.get_num_threads() > 1`` shares of the pixels of a round run in parallel (the kernel releases the
GIL; :func:`~torch_depth_sr.native.run_range`); with one thread the loop runs on the calling thread.

Sums and the exponent are in float64 whatever the input dtype (the torch path sums in the input dtype),
so in float32 ``P`` agrees with the torch path to float32 round-off and ``Q`` can differ only where ``P``
lies within round-off of ``τ``. Compiled by LLVM at first use and cached on disk (``cache=True``).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
import torch
from numba import njit

from .native import as_numpy, run_range

__all__ = ["singular_rounds_cpu", "support_cpu"]


@njit(cache=True, fastmath=False, nogil=True)
def _pixels(i0, i1, rnd, y0, obs, x, idx, w0, floor_, tau, tiny, need, q_old, q_new, p, dirty_old, dirty_new):
    """Q and P of pixels ``[i0, i1)`` of one sample in round ``rnd``; returns how many changed Q.

    ``y0, obs, x, q, p, dirty``: (HW,); ``idx, w0``: (k, HW). After the first round a pixel none of whose
    matched centres changed Q in the previous round keeps its Q and P: its statistics would be the same.
    ``need`` (HW,) uint8: a pixel is computed in rounds ``rnd < need`` only, and keeps its Q and P after them; 0
    entries: every pixel in every round.
    """
    first = rnd == 0
    with_need = need.shape[0] > 0
    k = idx.shape[0]
    xm = np.empty(k)  # the pixel's matched values and renormalised weights, read once
    wm = np.empty(k)
    changed = 0
    for ii in range(i0, i1):
        i = np.uint64(ii)  # unsigned: no wraparound test on each access (numba's, for negative signed indices)
        if with_need and need[i] <= rnd:
            q_new[i] = q_old[i]
            dirty_new[i] = 0
            continue
        if not first:
            stale = 0
            for m in range(k):
                stale |= dirty_old[np.uint64(idx[m, i])]
            if stale == 0:
                q_new[i] = q_old[i]
                dirty_new[i] = 0
                continue
        if obs[i] == 0:
            p[i] = 0.0
            q_new[i] = 0.0
            ch = q_old[i] != 0.0
            dirty_new[i] = ch
            changed += ch
            continue
        s = 0.0
        for m in range(k):
            j = np.uint64(idx[m, i])
            xm[m] = x[j]
            wm[m] = w0[m, i] * q_old[j]
            s += wm[m]
        if s > 0.0:
            # clamping s at the dtype's smallest normal number keeps a subnormal s from giving 1/s = inf
            # (as the torch path's clamp_min(tiny))
            inv = 1.0 / max(s, tiny)
            for m in range(k):
                wm[m] *= inv
        else:  # no matched centre is credible: all of them, with their original weights
            for m in range(k):
                wm[m] = w0[m, i]
        mu = 0.0
        for m in range(k):
            mu += wm[m] * xm[m]
        var = 0.0
        for m in range(k):
            d = xm[m] - mu
            var += wm[m] * d * d
        sigma = max(math.sqrt(max(var, 0.0)), floor_)
        r = y0[i] - mu
        pi = math.exp(-(r * r) / (2.0 * sigma * sigma))
        qi = 1.0 if pi >= tau else 0.0
        p[i] = pi
        q_new[i] = qi
        ch = qi != q_old[i]
        dirty_new[i] = ch
        changed += ch
    return changed


# ---- the support rule (singular.supported_or_line) in two passes over rows: each pixel's count of agreeing
# neighbours, then the rule, which reads the neighbours' counts (the middle of a chain).
_DY = np.array([-1, -1, -1, 0, 0, 1, 1, 1], dtype=np.int64)  # singular._OFFSETS: dy outer, dx inner, no centre
_DX = np.array([-1, 0, 1, -1, 1, -1, 0, 1], dtype=np.int64)


@njit(cache=True, nogil=True)
def _agreeing(t0, t1, y, obs, tol, count):
    """Rows ``[t0, t1)`` of the flattened (B, H): how many measured 8-neighbours of a measured pixel lie within
    ``tol[n]`` of it (0 at unmeasured pixels). ``y`` (B, H, W) holds 0 where ``obs`` (B, H, W) is 0. A row takes
    eight vector loops, one per neighbour, over the columns whose neighbour is inside the image."""
    _, h, w = y.shape
    for t in range(t0, t1):
        n = t // h
        i = t - n * h
        tl = tol[n]
        cnt = count[n, i]
        for j in range(w):
            cnt[j] = 0
        for d in range(8):
            yy = i + _DY[d]
            if yy < 0 or yy >= h:
                continue
            dx = _DX[d]
            j0 = max(0, -dx)
            j1 = min(w, w - dx)
            a = y[n, i, j0:j1]
            oa = obs[n, i, j0:j1]
            b = y[n, yy, j0 + dx:j1 + dx]
            ob = obs[n, yy, j0 + dx:j1 + dx]
            c = cnt[j0:j1]
            for j in range(j1 - j0):
                c[j] += oa[j] & ob[j] & (abs(b[j] - a[j]) <= tl)


@njit(cache=True, nogil=True)
def _support_rule(t0, t1, y, obs, tol, tol2, limits, support, count, out):
    """Rows ``[t0, t1)``: ``count >= support``, or a pixel on a line (``singular._lines``, the same tests in the
    same dtype). ``tol2`` = 2·tol and ``limits`` = (inf, −inf) in the dtype."""
    _, h, w = y.shape
    on = np.zeros(8, dtype=np.bool_)
    apart = np.zeros(8, dtype=np.bool_)
    for t in range(t0, t1):
        n = t // h
        i = t - n * h
        for j in range(w):
            c = count[n, i, j]
            if not obs[n, i, j]:
                out[n, i, j] = False
                continue
            if c >= support:
                out[n, i, j] = True
                continue
            if c > 2:  # more agreeing neighbours make a surface, not a line
                out[n, i, j] = False
                continue
            v = y[n, i, j]
            lo = limits[0]  # the extremes of the disagreeing neighbours, in the dtype (as its sums)
            hi = limits[1]
            chain = c >= 2
            for d in range(8):
                yy = i + _DY[d]
                xx = j + _DX[d]
                inside = 0 <= yy < h and 0 <= xx < w
                on[d] = inside and obs[n, yy, xx]
                agree = on[d] and abs(y[n, yy, xx] - v) <= tol[n]
                other = on[d] and not agree
                if other:
                    lo = min(lo, y[n, yy, xx])
                    hi = max(hi, y[n, yy, xx])
                apart[d] = other or not inside
                if agree and count[n, yy, xx] >= 2:  # the end of a chain: an agreeing neighbour in its middle
                    chain = True
            beyond = v <= lo - tol2[n] or v >= hi + tol2[n]
            between = False
            for d in range(4):  # offsets d and 7 - d are opposite
                between = between or (apart[d] and apart[7 - d] and (on[d] or on[7 - d]))
            out[n, i, j] = chain and beyond and between


def support_cpu(y: torch.Tensor, observed: torch.Tensor, tol: torch.Tensor, support: int) -> torch.Tensor:
    """``singular.supported_or_line`` of CPU float32/float64 tensors: ``y`` (B,1,H,W) with 0 where not measured,
    ``observed`` (B,1,H,W) bool (measured and finite), ``tol`` (B,) in ``y``'s dtype → (B,1,H,W) bool."""
    b, _, h, w = y.shape
    np_dt = np.float64 if y.dtype == torch.float64 else np.float32
    yn = as_numpy(y, (b, h, w), np_dt)
    on = as_numpy(observed, (b, h, w), np.bool_)
    tl = as_numpy(tol, (b,), np_dt)
    tl2 = as_numpy(2 * tol, (b,), np_dt)
    count = np.empty((b, h, w), np.int32)
    out = np.empty((b, h, w), np.bool_)
    run_range(_agreeing, b * h, yn, on, tl, count)
    limits = np.array([np.inf, -np.inf], np_dt)
    run_range(_support_rule, b * h, yn, on, tl, tl2, limits, int(support), count, out)
    return torch.from_numpy(out).view(b, 1, h, w)


def _rounds(y0, obs, x, idx, w0, floor_, tau, tiny, rounds, need, q, p):
    """All rounds for every sample (arrays (B, HW) and (B, k, HW)); ``q`` holds Q⁰ on entry, Q on exit; ``need``
    (B, HW) or (B, 0) as :func:`_pixels` reads it.

    The loop over samples and rounds is Python; each round is :func:`_pixels` over equal shares of the pixels on
    torch's thread count (it releases the GIL), or over all of them on the calling thread with one thread. A compiled
    loop with a ``numba.prange`` round inside compiled _pixels three times over (2.5 s more).
    """
    b, hw = y0.shape
    q_next = np.empty(hw, dtype=q.dtype)
    dirty = np.zeros(hw, dtype=np.uint8)
    dirty_next = np.zeros(hw, dtype=np.uint8)
    shares = 1 if need.shape[1] == 0 else 8  # a region's pixels are not spread evenly: more shares balance threads
    for n in range(b):
        for r in range(rounds):
            args = (r, y0[n], obs[n], x[n], idx[n], w0[n], floor_[n], tau, tiny, need[n], q[n], q_next, p[n], dirty,
                    dirty_next)
            changed = sum(run_range(_pixels, hw, *args, shares=shares))  # equal shares of the pixels per thread
            q[n] = q_next
            dirty, dirty_next = dirty_next, dirty
            if changed == 0:
                break


def singular_rounds_cpu(y0: torch.Tensor, obs: torch.Tensor, x: torch.Tensor, index: torch.Tensor,
                        weight: torch.Tensor, floor: torch.Tensor, tau: float, rounds: int,
                        need: Optional[torch.Tensor] = None) -> tuple[torch.Tensor, torch.Tensor]:
    """``(Q, P)`` of the singular test, each ``(B, 1, H, W)`` in ``y0``'s dtype, by the numba kernel.

    Args:
        y0: ``(B,1,H,W)`` float32/64 CPU observation, 0 where missing. ``obs``: ``(B,1,H,W)`` bool, measured.
        x: ``(B,1,H,W)`` current estimate. ``index``/``weight``: ``(B,k,H,W)`` matches and their weights.
        floor: ``(B,)`` (or broadcastable to it) σ floor; ``tau``: the threshold on P; ``rounds`` ≥ 1.
        need: None, or ``(B,1,H,W)`` integer: a pixel takes part in the rounds ``r < need`` only and keeps the Q and
            P of its last (Q⁰ and P = 0 where ``need`` is 0).
    """
    b, _, h, w = y0.shape
    k = index.shape[1]
    np_dt = np.float64 if y0.dtype == torch.float64 else np.float32
    y0n = as_numpy(y0, (b, h * w), np_dt)
    xn = as_numpy(x.to(y0.dtype), (b, h * w), np_dt)
    obsn = as_numpy(obs.to(torch.uint8), (b, h * w), np.uint8)
    idxn = as_numpy(index.to(torch.int64), (b, k, h * w), np.int64)
    wn = as_numpy(weight.to(y0.dtype), (b, k, h * w), np_dt)
    fl = np.ascontiguousarray(floor.detach().reshape(-1).expand(b).double().numpy())
    q = obsn.astype(np_dt)  # Q⁰ = measured (a fresh array: the inputs are never written)
    p = np.zeros((b, h * w), dtype=np_dt)
    nd = np.zeros((b, 0), np.uint8) if need is None else as_numpy(need.clamp(0, 255), (b, h * w), np.uint8)
    _rounds(y0n, obsn, xn, idxn, wn, fl, float(tau), float(np.finfo(np_dt).tiny), int(rounds), nd, q, p)
    return torch.from_numpy(q).view(b, 1, h, w), torch.from_numpy(p).view(b, 1, h, w)
