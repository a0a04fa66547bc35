"""One pass of the depth-gap-aware hole fill (``fill.py``, :func:`~torch_depth_sr.fill.fill_holes_sided`): a numba
kernel.

For each pixel of a list it reads its ``kernel_size²`` window once and returns what ``fill._fill_pixels`` returns:
``(estimate, confidence, spans a gap, side share, has a value, weak)``: the nearest-rank quantiles of the measured
values, the 2-means split seeded at them (two iterations), the side chosen by weight mass and the weighted mean of
that side. The torch path gathers ``(N, K²)`` (and ``(N, K², 3)`` for the colour) and runs ~60 small passes over
them. No gradient: the torch path serves whenever autograd needs one.

Each pixel's values come from its own window only, so the pixels split across threads give the same results for
any thread count (:func:`~torch_depth_sr.native.run_range`; with one thread the loop runs on the calling thread).
The quantiles and the 2-means are computed where the window's whole range exceeds ``gap`` only (elsewhere its
quantiles cannot either): ``share`` is 1 there (what ``fill_holes_sided`` stores where there is no gap; the torch
path returns the unused share of its 2-means split). Ranks near the ends of the measured values (the 0.1 and 0.9
quantiles) are found by keeping the values up to them from that end, others by sorting.
Sums and the colour weights' exp are in float64 (the torch path works in the input dtype); the quantities the torch path stores as tensors
(the quantiles' rank, the 2-means centres and midpoint, the thirds, the share and the confidence) are rounded to
the input dtype before they are compared, so the outputs agree with the torch path to the input dtype's
round-off. Where two sums tie in exact arithmetic (a hole midway between two sides, one colour everywhere), which
side wins depends on each path's summation order: the kernel takes the first side (the one below the 2-means
midpoint) unless the other has strictly more weight.
Compiled by LLVM at first use and cached on disk (``cache=True``).
"""
from __future__ import annotations

import numpy as np
import torch
from numba import njit

from .native import as_numpy, run_range

__all__ = ["fill_pixels_cpu"]

_MIN_SHARE_PIXELS = 256  # pixels per share below which one thread does the pass (a hand-off costs ~50 µs)
_SHARES_PER_THREAD = 4
_INSERTION_MAX = 64  # windows with at most this many measured values are sorted by insertion, larger by Shell sort
_SELECT_MAX = 16  # a rank at most this far from an end is found by keeping that end's values, without a sort


@njit(cache=True, nogil=True, inline="always")
def _rnd(v, single):
    """``v`` rounded to the input dtype (float32 when ``single``): a value the torch path holds in a tensor."""
    if single:
        return np.float64(np.float32(v))
    return v


@njit(cache=True, nogil=True, inline="always")
def _tail(n, k):
    """How many values :func:`_select` keeps for the rank ``k`` of ``n``: those up to it from the nearer end."""
    return min(k + 1, n - k)


@njit(cache=True, nogil=True)
def _select(vals, n, k, tail):
    """The ``k``-th smallest (0-based) of ``vals[:n]``: the ``_tail(n, k)`` smallest (or largest) values are kept
    sorted in ``tail`` while the values are read once (ranks near an end: a few insertions, mostly one compare)."""
    m = _tail(n, k)
    low = k + 1 <= n - k
    c = 0
    for i in range(n):
        v = vals[i]
        if c == m:  # full: only a value beyond the kept last one enters (and the last one leaves)
            if (v >= tail[m - 1]) if low else (v <= tail[m - 1]):
                continue
            p = m - 1
        else:
            p = c
            c += 1
        while p > 0 and ((tail[p - 1] > v) if low else (tail[p - 1] < v)):
            tail[p] = tail[p - 1]
            p -= 1
        tail[p] = v
    return tail[m - 1]


@njit(cache=True, fastmath=False, nogil=True)
def _pixels(t0, t1, bi, yi, xi, h, w, x, filled, conf, guide, has_guide, ws, wch, dy, dx, inv_2sc2, qlo, qhi,
            gap, min_share, match, single, est, c_new, spans, share, ok, weak):
    """``fill._fill_pixels`` at pixels ``[t0, t1)`` of the list ``(bi, yi, xi)``.

    ``x``, ``filled``, ``conf`` (B·H·W,) flat planes; ``guide`` (1 or B, C, H·W) the guide's planes (unread unless
    ``has_guide``); ``ws``, ``wch``, ``dy``, ``dx`` (K²,) the window (dy outer, dx inner) and its space weights as
    the torch path computes them; ``inv_2sc2`` = 1/(2σ_c²); ``qlo``, ``qhi``, ``gap``, ``min_share``, ``match``
    in the input dtype (``single``: float32). Writes ``est``, ``c_new``, ``share`` (input dtype) and ``spans``,
    ``ok``, ``weak`` (bool) at ``[t0, t1)``.
    """
    k2 = dy.shape[0]
    nch = guide.shape[1]
    r = 0
    for j in range(k2):
        r = max(r, abs(dy[j]), abs(dx[j]))
    off = np.empty(k2, dtype=np.int64)  # flat offsets of the window in a plane
    for j in range(k2):
        off[j] = dy[j] * w + dx[j]
    vw = np.empty(k2)  # the window's values, confidences, colour weights and measured flags, read once
    cw = np.empty(k2)
    wcw = np.empty(k2)
    mw = np.zeros(k2, dtype=np.bool_)
    srt = np.empty(k2)  # the measured values (sorted where a rank is far from both ends)
    tail = np.empty(_SELECT_MAX)
    gc = np.empty(nch)  # the pixel's colour
    for t in range(t0, t1):
        b = bi[t]
        y0 = yi[t]
        x0 = xi[t]
        base = b * h * w
        centre = y0 * w + x0  # in the plane
        gb = b if guide.shape[0] > 1 else 0
        if has_guide:
            for ch in range(nch):
                gc[ch] = guide[gb, ch, centre]
        interior = y0 >= r and y0 < h - r and x0 >= r and x0 < w - r
        n = 0
        wcmax = 0.0
        vmin = np.inf
        vmax = -np.inf
        den0 = 0.0
        sv0 = 0.0
        sc0 = 0.0
        den1 = 0.0
        sv1 = 0.0
        sc1 = 0.0
        for j in range(k2):
            if interior:
                f = centre + off[j]
                inside = True
            else:
                yy = y0 + dy[j]
                xx = x0 + dx[j]
                inside = yy >= 0 and yy < h and xx >= 0 and xx < w
                f = min(max(yy, 0), h - 1) * w + min(max(xx, 0), w - 1)
            vw[j] = x[base + f]
            cw[j] = conf[base + f]
            mw[j] = filled[base + f] and inside
            if not mw[j]:  # a hole or outside: none of its weights is read
                continue
            wc = 1.0
            if has_guide:
                d2 = 0.0
                for ch in range(nch):
                    d = np.float64(guide[gb, ch, f]) - gc[ch]
                    d2 += d * d
                # in float64 for float32 inputs too: float32's exp of a colour far off is subnormal (slow)
                wc = np.exp(-d2 * inv_2sc2)
            wcw[j] = wc
            # the weighted mean of the whole window (what a window with no gap takes), with and without the colour
            u = ws[j] * wc
            den1 += u
            sv1 += u * vw[j]
            sc1 += u * cw[j]
            den0 += ws[j]
            sv0 += ws[j] * vw[j]
            sc0 += ws[j] * cw[j]
            srt[n] = vw[j]
            n += 1
            if wc > wcmax:
                wcmax = wc
            vmin = min(vmin, vw[j])
            vmax = max(vmax, vw[j])
        has = n > 0
        is_weak = has_guide and wcmax < match
        # the window spans a gap when the spread of its nearest-rank quantiles exceeds ``gap``; it cannot when the
        # whole range does not: then neither the quantiles nor the 2-means are needed (share 1, as fill stores it)
        gapped = has and _rnd(vmax - vmin, single) > gap
        lo = 0.0
        hi = 0.0
        mid = 0.0
        top_a = 0.0
        bottom_b = 0.0
        pick_b = False
        sh = 1.0
        if gapped:
            # the quantiles: rank round((n-1)·q) in the input dtype, half to even
            klo = int(np.rint(_rnd(_rnd(n - 1, single) * qlo, single)))
            khi = int(np.rint(_rnd(_rnd(n - 1, single) * qhi, single)))
            if max(_tail(n, klo), _tail(n, khi)) <= _SELECT_MAX:  # ranks near the ends: kept tails, no sort
                lo = _select(srt, n, klo, tail)
                hi = _select(srt, n, khi, tail)
            else:
                if n <= _INSERTION_MAX:
                    for i in range(1, n):
                        key = srt[i]
                        p = i - 1
                        while p >= 0 and srt[p] > key:
                            srt[p + 1] = srt[p]
                            p -= 1
                        srt[p + 1] = key
                else:  # Shell sort: np.sort here compiled 4.5 s longer (its quicksort and a shape check)
                    step = 1
                    while step < n // 3:
                        step = 3 * step + 1
                    while step > 0:
                        for i in range(step, n):
                            key = srt[i]
                            p = i - step
                            while p >= 0 and srt[p] > key:
                                srt[p + step] = srt[p]
                                p -= step
                            srt[p + step] = key
                        step //= 3
                lo = srt[klo]
                hi = srt[khi]
            gapped = _rnd(hi - lo, single) > gap
        if gapped:
            # 2-means seeded at the quantiles, two iterations
            ca = lo
            cb = hi
            for _it in range(2):
                mid = _rnd(ca + cb, single) * 0.5
                sa = 0.0
                sb = 0.0
                na = 0
                nb = 0
                for j in range(k2):
                    if mw[j]:
                        if vw[j] > mid:
                            sb += vw[j]
                            nb += 1
                        else:
                            sa += vw[j]
                            na += 1
                if na > 0:
                    ca = _rnd(sa / na, single)
                if nb > 0:
                    cb = _rnd(sb / nb, single)
            third = _rnd(_rnd(cb - ca, single) / 3.0, single)
            top_a = _rnd(ca + third, single)
            bottom_b = _rnd(cb - third, single)
            # the sides' weight masses under the choice weights
            wa = 0.0
            wb = 0.0
            for j in range(k2):
                if mw[j]:
                    wj = wch[j] if is_weak else wch[j] * wcw[j]
                    if vw[j] > mid:
                        if vw[j] >= bottom_b:
                            wb += wj
                    elif vw[j] <= top_a:
                        wa += wj
            pick_b = wb > wa
            tot = wa + wb
            sh = _rnd(max(wa, wb) / (tot if tot > 1e-30 else 1e-30), single)
        # the weighted mean of the chosen side (of the whole window when it spans no gap)
        if not gapped:  # summed while the window was read
            den = den0 if is_weak else den1
            sv = sv0 if is_weak else sv1
            sc = sc0 if is_weak else sc1
        else:
            den = 0.0
            sv = 0.0
            sc = 0.0
            for j in range(k2):
                if mw[j]:
                    if pick_b:
                        if not (vw[j] > mid and vw[j] >= bottom_b):
                            continue
                    elif not (vw[j] <= mid and vw[j] <= top_a):
                        continue
                    u = ws[j] if is_weak else ws[j] * wcw[j]
                    den += u
                    sv += u * vw[j]
                    sc += u * cw[j]
        dd = den if den > 1e-30 else 1e-30
        c_in = _rnd(sc / dd, single)
        cn = 1.0 if c_in > 0.5 else 0.0
        if gapped and not sh >= min_share:
            cn = 0.0
        est[t] = sv / dd
        c_new[t] = cn
        spans[t] = gapped
        share[t] = sh
        ok[t] = has and den > 0.0
        weak[t] = is_weak


def fill_pixels_cpu(p: tuple, bi: torch.Tensor, yi: torch.Tensor, xi: torch.Tensor, match: float) -> tuple:
    """``fill._fill_pixels(p, bi, yi, xi)`` by the kernel: ``(est, c_new, spans, share, ok, weak)``, each (N,).

    Args:
        p: the ``fill._FillPlanes`` of a CPU float32/float64 fill (read, not written).
        bi, yi, xi: (N,) int64 pixel coordinates.
        match: the colour weight above which a neighbour looks like the pixel (``fill._MATCH``).
    """
    b, h, w = p.x.shape[0], p.h, p.w
    single = p.x.dtype == torch.float32
    np_dt = np.float32 if single else np.float64
    cast = np.float32 if single else np.float64
    xn = as_numpy(p.x, (b * h * w,), np_dt)
    fn = as_numpy(p.filled, (b * h * w,), np.bool_)
    cn = as_numpy(p.conf, (b * h * w,), np_dt)
    has_guide = p.guide is not None
    gn = (as_numpy(p.guide, (p.guide.shape[0], p.guide.shape[1], h * w), np_dt) if has_guide
          else np.zeros((1, 1, 1), np_dt))
    ws = as_numpy(p.ws, (-1,), np.float64)  # the torch path's weights (in its dtype), exactly
    wch = as_numpy(p.wch, (-1,), np.float64)
    dyn = as_numpy(p.dy, (-1,), np.int64)
    dxn = as_numpy(p.dx, (-1,), np.int64)
    bn = as_numpy(bi, (-1,), np.int64)
    yn = as_numpy(yi, (-1,), np.int64)
    xin = as_numpy(xi, (-1,), np.int64)
    total = bn.shape[0]
    est = np.empty(total, np_dt)
    c_new = np.empty(total, np_dt)
    share = np.empty(total, np_dt)
    spans = np.empty(total, np.bool_)
    ok = np.empty(total, np.bool_)
    weak = np.empty(total, np.bool_)
    args = (bn, yn, xin, h, w, xn, fn, cn, gn, has_guide, ws, wch, dyn, dxn, 1.0 / (2.0 * p.sigma_color ** 2),
            float(cast(p.quantiles[0])), float(cast(p.quantiles[1])), float(cast(p.gap)), float(cast(p.min_share)),
            float(cast(match)), single, est, c_new, spans, share, ok, weak)
    run_range(_pixels, total, *args, shares=_SHARES_PER_THREAD, min_share=_MIN_SHARE_PIXELS)
    return tuple(torch.from_numpy(a) for a in (est, c_new, spans, share, ok, weak))
