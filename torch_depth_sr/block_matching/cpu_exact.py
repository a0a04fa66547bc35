"""Exact block matching on the CPU: a numba kernel, compiled by LLVM at first use (no C compiler).

Shift-and-box-filter with a running top-``k`` per pixel. For every offset ``o`` of the search window
the squared differences of a band of image rows are summed over the block by a ring buffer of
``b`` rows (column sums) and a sliding row sum, and each pixel's distance is offered to its sorted
list of the ``k`` best. The distance is symmetric, ``d(p, p+o) = d(p+o, p)``, so only one offset of
each mirrored pair is computed and offered to both pixels. Offsets are visited nearest first, so the
``k``-th distance is tight early and few offers need an insertion. Keys compare as ``(distance, offset
id)``: ties go to the smaller id whatever the visiting order, as in the unfold reference. A band keeps
its lists rank-major, so that a row's offer is a vector test against the k-th distances, and (short
lists, many insertions) a branch-free vector merge of every rank. In float32 each entry is one uint64 key, the
distance's bits above the offset id, which orders as the pair does: a rank's merge is then a max and a min.

Bands of rows run in parallel: the kernels release the GIL (``nogil=True``) and
:func:`~torch_depth_sr.native.run_tasks` runs the bands on ``torch.get_num_threads()`` threads (rather than
``numba.prange``, which compiled 2.5 times longer). The compiled code is cached on disk by numba (``cache=True``).
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import torch
from numba import njit, types
from numba.extending import overload

from ..native import run_range, run_tasks
from ._common import offset_order, symmetric_order

__all__ = ["block_match_cpu_exact", "block_match_cpu_exact_at"]

_ID_NONE = np.int32(0x7FFFFFFF)


# ---- the running top-k lists of a band of rows, rank-major: a row's lists are (k, W) arrays, rank m of every pixel of
# the row contiguous, so that offering a row of candidate distances (one offset of the window) is a few vector loops.
# They live in this file with _band, which calls them: numba's on-disk cache of a function is invalidated only by a
# change of its own source file, and _band's compiled code contains them.
@njit(cache=True, inline="always")
def _beats(d, oid, e, eid):
    """Whether key ``(d, oid)`` sorts before ``(e, eid)`` (short-circuit: for the column-by-column insertion)."""
    return d < e or (d == e and oid < eid)


@njit(cache=True, inline="always")
def _beats_vector(d, oid, e, eid):
    """:func:`_beats` without branches, for the loops over a row that LLVM vectorises. Not for the column-by-column
    insertion: there this form made the k = 40 search about 40 % slower than the short-circuit one."""
    return (d < e) | ((d == e) & (oid < eid))


@njit(cache=True, nogil=True)
def _count_beating(dv, last_d, last_i, oid):
    """How many of ``dv[j]`` (with id ``oid``) beat the k-th entries ``last_d[j], last_i[j]`` (a vector loop)."""
    n = 0
    for j in range(dv.shape[0]):
        n += _beats_vector(dv[j], oid, last_d[j], last_i[j])
    return n


@njit(cache=True, nogil=True)
def _insert_few(dv, rd, ri, a0, oid, seeded):
    """Insert ``dv[j]`` into the rank-major lists ``rd, ri`` (k, W) of column ``a0 + j`` where it beats the k-th."""
    k = rd.shape[0]
    for j in range(dv.shape[0]):
        d = dv[j]
        jj = a0 + j
        if not _beats(d, oid, rd[k - 1, jj], ri[k - 1, jj]):
            continue
        if seeded and _listed_rank(oid, ri, jj):
            continue
        m = k - 1
        while m > 0 and _beats(d, oid, rd[m - 1, jj], ri[m - 1, jj]):
            rd[m, jj] = rd[m - 1, jj]
            ri[m, jj] = ri[m - 1, jj]
            m -= 1
        rd[m, jj] = d
        ri[m, jj] = oid


@njit(cache=True, nogil=True)
def _merge_rank(dv, cd, ci, pd, pi, oid):
    """Rank m of every column after offering ``dv`` (a vector loop, no branches): the entry of rank m-1
    (``pd, pi``) if the offer beats it, else the offer if it beats rank m (``cd, ci``), else rank m unchanged."""
    for j in range(dv.shape[0]):
        d = dv[j]
        c = cd[j]
        c_id = ci[j]
        p = pd[j]
        p_id = pi[j]
        above = _beats_vector(d, oid, p, p_id)
        here = _beats_vector(d, oid, c, c_id)
        cd[j] = p if above else (d if here else c)
        ci[j] = p_id if above else (oid if here else c_id)


@njit(cache=True, nogil=True)
def _merge_first(dv, cd, ci, oid):
    """Rank 0 of every column after offering ``dv``."""
    for j in range(dv.shape[0]):
        d = dv[j]
        c = cd[j]
        c_id = ci[j]
        here = _beats_vector(d, oid, c, c_id)
        cd[j] = d if here else c
        ci[j] = oid if here else c_id


@njit(cache=True, nogil=True)
def _offer_row(dd, j0, j1, a0, oid, rd, ri, seeded):
    """Offer the distances ``dd[j0:j1]`` (id ``oid``) to the rank-major lists ``rd, ri`` (k, W) of the columns
    ``a0 ...``. Late offsets (most of them, nearest first) beat no list of the row: one vector count skips them.
    Early ones beat many: with a short list, every rank is rewritten by a branch-free vector loop; otherwise,
    and for few insertions, one column at a time. At 640x480 on one thread, k = 10 of a 7x7 window: 0.27-0.38 ->
    0.12-0.16 s for the whole search (the pixel-major lists tested and inserted pixel by pixel); k = 40 of 15x15:
    no change beyond the noise (1.8-2.4 s either way), whichever split of the two ways."""
    if j1 <= j0:  # no column of the row has this candidate inside the image (a slice would wrap a negative end)
        return
    k = rd.shape[0]
    a1 = a0 + (j1 - j0)
    dv = dd[j0:j1]
    n = _count_beating(dv, rd[k - 1, a0:a1], ri[k - 1, a0:a1], oid)
    if n == 0:
        return
    if seeded or k > 16 or n * 16 < j1 - j0:
        _insert_few(dv, rd, ri, a0, oid, seeded)
        return
    for m in range(k - 1, 0, -1):
        _merge_rank(dv, rd[m, a0:a1], ri[m, a0:a1], rd[m - 1, a0:a1], ri[m - 1, a0:a1], oid)
    _merge_first(dv, rd[0, a0:a1], ri[0, a0:a1], oid)


@njit(cache=True, inline="always")
def _listed_rank(oid, ri, j):
    """:func:`_listed` for rank-major lists ``ri`` (k, W)."""
    for m in range(ri.shape[0]):
        if ri[m, j] == oid:
            return True
    return False


# ---- float32: each list entry packed into one uint64 key, the distance's bits above the offset id. A distance is
# never negative or NaN (clamped at 0 before it is offered), and the bits of such floats order as the floats do, so
# the keys order exactly as the pairs (distance, offset id): an offer to a rank is one max and one min, where the
# pairs take several compares and selects (float64 has no room for the id and keeps the pairs).
_HIGH = np.uint64(32)
_LOW = np.uint64(0xFFFFFFFF)


@njit(cache=True, nogil=True)
def _pack(rd, ri, keys):
    """The lists ``rd`` (float32) and ``ri`` (int32) as ``keys``, each (rows, k, W), C-contiguous."""
    bits, ids, out = rd.view(np.uint32).ravel(), ri.ravel(), keys.ravel()
    for t in range(out.shape[0]):
        out[t] = (np.uint64(bits[t]) << _HIGH) | np.uint64(np.uint32(ids[t]))


@njit(cache=True, nogil=True)
def _unpack(keys, rd, ri):
    """:func:`_pack` undone."""
    bits, ids, src = rd.view(np.uint32).ravel(), ri.ravel(), keys.ravel()
    for t in range(src.shape[0]):
        bits[t] = np.uint32(src[t] >> _HIGH)
        ids[t] = np.int32(src[t] & _LOW)


@njit(cache=True, nogil=True)
def _offer_keys(high, j0, j1, a0, oid, keys, seeded):
    """:func:`_offer_row` for the key lists ``keys`` (k, W) of a row: ``high`` holds the distances' bits shifted
    into place (``uint64(bits) << 32``), the keys offered are ``high[j] | oid``."""
    if j1 <= j0:
        return
    k = keys.shape[0]
    n = j1 - j0
    hv = high[j0:j1]
    o = np.uint64(oid)
    last = keys[k - 1, a0:a0 + n]
    count = 0
    for j in range(n):
        count += (hv[j] | o) < last[j]
    if count == 0:
        return
    if seeded or k > 16 or count * 16 < n:
        for j in range(n):
            key = hv[j] | o
            jj = a0 + j
            if not key < keys[k - 1, jj]:
                continue
            if seeded and _listed_key(o, keys, jj):
                continue
            m = k - 1
            while m > 0 and key < keys[m - 1, jj]:
                keys[m, jj] = keys[m - 1, jj]
                m -= 1
            keys[m, jj] = key
        return
    for m in range(k - 1, 0, -1):  # rank m after the offer: rank m-1 if the offer beats it, else the smaller
        c = keys[m, a0:a0 + n]
        p = keys[m - 1, a0:a0 + n]
        for j in range(n):
            c[j] = min(max(hv[j] | o, p[j]), c[j])
    c = keys[0, a0:a0 + n]
    for j in range(n):
        c[j] = min(hv[j] | o, c[j])


@njit(cache=True, inline="always")
def _listed_key(o, keys, j):
    """:func:`_listed_rank` for key lists."""
    for m in range(keys.shape[0]):
        if keys[m, j] & _LOW == o:
            return True
    return False


_NO_KEY = np.uint64(0xFFFFFFFFFFFFFFFF)  # sorts after every key: an offer of it changes no list


# ---- which lists a band runs, chosen when numba types _band's ``keys`` (None, or an array): only that way is compiled
def _lists_pack(rd, ri, keys):
    """The lists as keys when ``keys`` is an array (:func:`_pack`); nothing when None. Compiled code only."""
    raise NotImplementedError


def _lists_unpack(keys, rd, ri):
    """:func:`_unpack` when ``keys`` is an array; nothing when None. Compiled code only."""
    raise NotImplementedError


def _lists_offer(dd, high, j0, j1, a0, oid, rd, ri, keys, row, seeded):
    """Offer row ``row``'s lists the distances ``dd[j0:j1]`` with offset id ``oid`` (:func:`_offer_row`), or, with
    keys, the keys ``high[j] | oid`` (:func:`_offer_keys`; ``high`` filled by :func:`_lists_high`)."""
    raise NotImplementedError


def _lists_high(dd, high, j0, j1, keys):
    """With keys, ``high[j0:j1]`` = the distances' bits shifted into the keys' high halves; else nothing."""
    raise NotImplementedError


def _keyed(keys) -> bool:
    return not isinstance(keys, (types.NoneType, types.Omitted))


def _only_allowed(dd, high, j0, j1, masks, row, c0, oid, dm, hm):
    """The offer of offset ``oid`` to the pixels ``(row, c0 + j - j0)``, ``j`` in ``[j0, j1)``: ``(dd, high)`` as
    they are when ``masks`` is None; else copies ``(dm, hm)`` in which a pixel whose candidate bit ``oid`` is not set
    in ``masks`` (words, H, W) offers what beats no list (NaN, all-ones keys)."""
    raise NotImplementedError


@overload(_lists_pack)
def _ol_lists_pack(rd, ri, keys):
    if _keyed(keys):
        return lambda rd, ri, keys: _pack(rd, ri, keys)
    return lambda rd, ri, keys: None


@overload(_lists_unpack)
def _ol_lists_unpack(keys, rd, ri):
    if _keyed(keys):
        return lambda keys, rd, ri: _unpack(keys, rd, ri)
    return lambda keys, rd, ri: None


@overload(_lists_offer)
def _ol_lists_offer(dd, high, j0, j1, a0, oid, rd, ri, keys, row, seeded):
    if _keyed(keys):
        def offer_keys(dd, high, j0, j1, a0, oid, rd, ri, keys, row, seeded):
            _offer_keys(high, j0, j1, a0, np.int64(oid), keys[row], seeded)
        return offer_keys

    def offer_pairs(dd, high, j0, j1, a0, oid, rd, ri, keys, row, seeded):
        _offer_row(dd, j0, j1, a0, np.int32(oid), rd[row], ri[row], seeded)
    return offer_pairs


@overload(_only_allowed)
def _ol_only_allowed(dd, high, j0, j1, masks, row, c0, oid, dm, hm):
    if not _keyed(masks):
        return lambda dd, high, j0, j1, masks, row, c0, oid, dm, hm: (dd, high)

    def masked(dd, high, j0, j1, masks, row, c0, oid, dm, hm):
        bit = np.uint64(1) << np.uint64(oid & 63)
        m = masks[oid >> 6, row, c0:c0 + (j1 - j0)]
        dv, hv, dmv, hmv = dd[j0:j1], high[j0:j1], dm[j0:j1], hm[j0:j1]
        nan = dd[0] - dd[0] + np.nan
        for j in range(j1 - j0):
            ok = (m[j] & bit) != 0
            dmv[j] = dv[j] if ok else nan
            hmv[j] = hv[j] if ok else _NO_KEY
        return dm, hm
    return masked


@overload(_lists_high)
def _ol_lists_high(dd, high, j0, j1, keys):
    if _keyed(keys):
        def fill(dd, high, j0, j1, keys):
            bits = dd.view(np.uint32)[j0:j1]
            hv = high[j0:j1]
            for j in range(j1 - j0):
                hv[j] = np.uint64(bits[j]) << _HIGH
        return fill
    return lambda dd, high, j0, j1, keys: None


@njit(cache=True, error_model="numpy", nogil=True)
def _band(xp, tp, cp, use_t, big_h, big_w, r, big_r, order, both, consts, h0, h1, wa, wb, topd, topi, seeded, dist,
          index, keys, masks, where):
    """Running top-k for image rows [h0, h1); ``topd/topi`` are (h1-h0, W, k) views of this band: the working lists,
    read when ``seeded`` and written at the end, unless ``dist`` and ``index`` (k, H, W) are not empty: then the band
    writes its rows of the final distances and flat indices there instead (what :func:`_finalize` would make).
    ``keys``: None, or for float32 planes a (h1-h0, k, W) uint64 array in which the lists run as packed keys
    (the ``_lists_*`` overloads: numba compiles only the way the argument's type selects). ``masks``: None, or
    (words, H, W) uint64 bits of the offsets each pixel may keep (:func:`_only_allowed`; the re-matching's candidates).
    ``[wa, wb)``: the image columns the band searches (the whole width, or a window of a masked search): a pixel of
    the window is offered only candidates inside it, so its lists are the whole image's where the window reaches the
    search radius beyond it (rows and planes are the whole image's: the sums run in the same order). ``where``: (H, W)
    uint8, or (0, 0) for every pixel: the pixels whose final matches the band writes (with ``dist``).

    ``xp, tp`` (Hp, Wp) and ``cp`` (C, Hp, Wp): planes replicate-padded by r, then zero-padded by R.
    ``consts`` = (ρ/C, ρ/(C·b²), 1/b²) in the planes' dtype, so that float32 stays float32 (SIMD width).
    """
    bs = 2 * r + 1
    s = 2 * big_r + 1
    u_len = big_w + 2 * r
    nw = wb - wa  # the window's columns: the lists' width
    u0, u1 = wa, wb + 2 * r  # the columns of the padded planes its block sums read
    nu = u1 - u0
    nc = cp.shape[0]
    cw, crho, inb = consts[0], consts[1], consts[2]
    one = consts[3]
    zero = consts[4]
    nbuf = 3 if use_t else 1
    ring = np.zeros((nbuf, bs, u_len), dtype=xp.dtype)  # depth (, trust product, colour) squared differences
    col = np.zeros((nbuf, u_len), dtype=xp.dtype)
    dd = np.zeros(big_w, dtype=xp.dtype)
    trust_sum = np.zeros(big_w, dtype=xp.dtype)  # a row's block sums of the trust product and colour
    colour_sum = np.zeros(big_w, dtype=xp.dtype)
    k = topd.shape[2]
    # the band's lists rank-major, (rows, k, W): rank m of a row is contiguous, so an offer to a row is vector loops
    rd = np.empty((h1 - h0, k, nw), dtype=xp.dtype)
    ri = np.empty((h1 - h0, k, nw), dtype=np.int32)
    for a in range(h1 - h0):
        for m in range(k):
            for j in range(nw):
                rd[a, m, j] = topd[a, wa + j, m] if seeded else np.inf
                ri[a, m, j] = topi[a, wa + j, m] if seeded else _ID_NONE
    high = np.zeros(big_w, dtype=np.uint64)  # a row's distances as the high halves of keys
    dm = np.zeros(big_w, dtype=xp.dtype)  # the same, with the offers of the candidates a pixel may not keep voided
    hm = np.zeros(big_w, dtype=np.uint64)
    _lists_pack(rd, ri, keys)
    for io in range(order.shape[0]):
        oid = order[io]
        dy = oid // s - big_r
        dx = oid % s - big_r
        mid = (big_r - dy) * s + (big_r - dx)
        f0 = max(h0, -dy)
        f1 = min(h1, big_h - dy)  # rows i of the band whose candidate row i+dy is inside
        i0, i1 = f0, f1
        m0, m1 = 0, 0  # rows i whose mirrored pixel (i+dy, j+dx) lies in the band
        if both[io]:
            m0 = max(h0 - dy, 0)
            m1 = min(h1 - dy, big_h - dy)
            if m1 > m0:
                if f1 <= f0:
                    i0, i1 = m0, m1
                else:
                    i0, i1 = min(i0, m0), max(i1, m1)
        # columns j of the window whose candidate j + dx lies in it too (the whole image's: inside the image)
        j0 = wa + (-dx if dx < 0 else 0)
        j1 = wb - (dx if dx > 0 else 0)
        if i1 <= i0 or j1 <= j0:
            continue
        for t in range(i0, i1 + 2 * r):
            slot = t % bs
            xa = xp[big_r + t, big_r + u0:big_r + u1]
            xb = xp[big_r + t + dy, big_r + dx + u0:big_r + dx + u1]
            e = ring[0, slot, u0:u1]
            if use_t:
                ta = tp[big_r + t, big_r + u0:big_r + u1]
                tb = tp[big_r + t + dy, big_r + dx + u0:big_r + dx + u1]
                et = ring[1, slot, u0:u1]
                ec = ring[2, slot, u0:u1]
                for u in range(nu):
                    tt = ta[u] * tb[u]
                    df = xa[u] - xb[u]
                    e[u] = tt * (df * df)
                    et[u] = tt
                    ec[u] = zero
                for c in range(nc):
                    ca = cp[c, big_r + t, big_r + u0:big_r + u1]
                    cb = cp[c, big_r + t + dy, big_r + dx + u0:big_r + dx + u1]
                    for u in range(nu):
                        dc = ca[u] - cb[u]
                        ec[u] += dc * dc
            else:
                for u in range(nu):
                    df = xa[u] - xb[u]
                    e[u] = df * df
                for c in range(nc):
                    ca = cp[c, big_r + t, big_r + u0:big_r + u1]
                    cb = cp[c, big_r + t + dy, big_r + dx + u0:big_r + dx + u1]
                    for u in range(nu):
                        dc = ca[u] - cb[u]
                        e[u] += cw * (dc * dc)
            if t < i0 + 2 * r:
                continue
            i = t - 2 * r
            for bb in range(nbuf):
                cs = col[bb, u0:u1]
                rb0 = ring[bb, 0, u0:u1]
                for u in range(nu):
                    cs[u] = rb0[u]
                for s2 in range(1, bs):
                    rbs = ring[bb, s2, u0:u1]
                    for u in range(nu):
                        cs[u] += rbs[u]
            # the row's distances in loops that start at 0: numba wraps a negative index around, and LLVM vectorises
            # a loop only where it can tell the index is not negative (from j0 it could not: half the time)
            nj = j1 - j0
            ddv = dd[j0:j1]
            c0 = col[0, j0:j1 + bs - 1]
            for j in range(nj):
                ddv[j] = c0[j]
            for q in range(1, bs):
                for j in range(nj):
                    ddv[j] += c0[j + q]
            if use_t:
                c1 = col[1, j0:j1 + bs - 1]
                c2 = col[2, j0:j1 + bs - 1]
                s1 = trust_sum[:nj]
                sc = colour_sum[:nj]
                for j in range(nj):
                    s1[j] = c1[j]
                    sc[j] = c2[j]
                for q in range(1, bs):
                    for j in range(nj):
                        s1[j] += c1[j + q]
                        sc[j] += c2[j + q]
                for j in range(nj):
                    ddv[j] = ddv[j] / max(s1[j], one) + crho * sc[j]
            else:
                for j in range(nj):
                    ddv[j] *= inb
            for j in range(nj):
                if not ddv[j] > zero:
                    ddv[j] = zero
            _lists_high(dd, high, j0, j1, keys)
            if i >= f0 and i < f1:  # pixel (i, j) gets candidate (i+dy, j+dx)
                dv, hv = _only_allowed(dd, high, j0, j1, masks, i, j0, oid, dm, hm)
                _lists_offer(dv, hv, j0, j1, j0 - wa, np.int64(oid), rd, ri, keys, i - h0, seeded)
            if i >= m0 and i < m1:  # pixel (i+dy, j+dx) gets candidate (i, j)
                dv, hv = _only_allowed(dd, high, j0, j1, masks, i + dy, j0 + dx, mid, dm, hm)
                _lists_offer(dv, hv, j0, j1, j0 + dx - wa, mid, rd, ri, keys, i + dy - h0, seeded)
    _lists_unpack(keys, rd, ri)
    every = where.shape[0] == 0
    if dist.size > 0:
        for a in range(h1 - h0):
            i = h0 + a
            for m in range(k):
                for jj in range(nw):
                    j = wa + jj
                    if not every and where[i, j] == 0:
                        continue
                    oid = ri[a, m, jj]
                    dist[m, i, j] = rd[a, m, jj]
                    index[m, i, j] = (i + oid // s - big_r) * big_w + (j + oid % s - big_r)
        return
    for a in range(h1 - h0):
        for jj in range(nw):
            for m in range(k):
                topd[a, wa + jj, m] = rd[a, m, jj]
                topi[a, wa + jj, m] = ri[a, m, jj]


def _pad(planes: torch.Tensor, r: int, big_r: int, dtype) -> np.ndarray:
    """(B, C, H, W) → numpy (B, C, H+2r+2R, W+2r+2R): replicate by r, then zeros by R."""
    p = torch.nn.functional.pad(planes.to(dtype), (r,) * 4, mode="replicate")
    p = torch.nn.functional.pad(p, (big_r,) * 4)
    return np.ascontiguousarray(p.cpu().numpy())


@njit(cache=True, nogil=True, error_model="numpy")  # no zero-division checks: as when it was a prange body
def _finalize(topd, topi, big_r, dist, index, n0, n1):
    """Working lists (B, H, W, k) of distances and offset ids → ``dist`` and flat ``index``, each (B, k, H, W), for
    the rows ``[n0, n1)`` of the flattened (B·H) batch."""
    bsz, h, w, k = topd.shape
    s = 2 * big_r + 1
    for n in range(n0, n1):
        b = n // h
        i = n % h
        for j in range(w):
            for m in range(k):
                oid = topi[b, i, j, m]
                dist[b, m, i, j] = topd[b, i, j, m]
                index[b, m, i, j] = (i + oid // s - big_r) * w + (j + oid % s - big_r)


def finalize(topd: np.ndarray, topi: np.ndarray, search_window: int) -> tuple:
    """``(dist, index)`` tensors (B, k, H, W) from the kernels' working lists (one parallel pass, no copies in torch)."""
    bsz, h, w, k = topd.shape
    dist = np.empty((bsz, k, h, w), dtype=topd.dtype)
    index = np.empty((bsz, k, h, w), dtype=np.int64)
    run_range(lambda n0, n1: _finalize(topd, topi, search_window // 2, dist, index, n0, n1), bsz * h)  # rows
    return torch.from_numpy(dist), torch.from_numpy(index)


def padded_planes(depth, rgb, trust, r: int, big_r: int):
    """``(xp, tp, cp, use_t)``: the numpy planes the kernels read (see :func:`_band`)."""
    bsz = depth.shape[0]
    dt = torch.float64 if depth.dtype == torch.float64 else torch.float32
    xp = _pad(depth.detach(), r, big_r, dt)[:, 0]
    use_t = trust is not None
    tp = _pad(trust.detach(), r, big_r, dt)[:, 0] if use_t else np.zeros((bsz, 1, 1), xp.dtype)
    cp = _pad(rgb.detach(), r, big_r, dt) if rgb is not None else np.zeros((bsz, 0, 1, 1), xp.dtype)
    return xp, tp, cp, use_t


def search(planes, h, w, block_size, search_window, rho, include_self, chunk_rows, stride, topd, topi, seeded,
           out=None, masks=None, where=None):
    """Run the exact search over the offsets of the ``stride`` lattice into the working lists ``topd/topi``
    (B, H, W, k); with ``seeded`` they start from the candidates already in them. With ``out = (dist, index)``
    (B, k, H, W) and lists that are not seeded, the bands write the final matches there instead (``topd/topi``
    unused: pass None). With ``masks`` (B, words, H, W) uint64, a pixel keeps only the offsets whose bits are set
    (offset id ``o``: bit ``o % 64`` of word ``o // 64``). With ``where`` (B, H, W) bool and ``out``, only those
    pixels are searched and written (:func:`_windows`); the rest of ``out`` is left as it was."""
    xp, tp, cp, use_t = planes
    bsz = xp.shape[0]
    k = out[0].shape[1] if out is not None else topd.shape[-1]
    if out is None:  # empty outputs tell the kernel to write the working lists
        dist, index = np.empty((1, k, 0, w), xp.dtype), np.empty((1, k, 0, w), np.int64)
        out_of = lambda b: (dist[0], index[0])  # noqa: E731
    else:
        dist, index = out
        out_of = lambda b: (dist[b], index[b])  # noqa: E731
        topd = np.empty((bsz, 0, w, k), xp.dtype)  # of the type of the working lists' views, and empty
        topi = np.empty((bsz, 0, w, k), np.int32)
    r, big_r = block_size // 2, search_window // 2
    order, both = symmetric_order(offset_order(search_window, stride, include_self), search_window)
    # taller bands share more of each mirrored pair's rows; at least one band per thread; and a band's lists (what
    # the insertions touch at random) within ~2 MiB, the size of a core's cache: at 640x480, k = 40, 10 rows rather
    # than 32 ran the search ~15 % faster (the shifts of the insertions themselves are cheap, a heap did not help)
    fit = (2 << 20) // (w * k * (xp.itemsize + 4))
    rows = chunk_rows or max(8, min(32, -(-h // max(1, torch.get_num_threads())), fit))
    bands = [(b, h0, min(h, h0 + rows), 0, w) for b in range(bsz) for h0 in range(0, h, rows)]  # the whole image
    only = np.zeros((bsz, 0, 0), np.uint8)
    if where is not None:  # the windows of the pixels, unless they would cover most of the image
        windows = _windows(where, min(rows, _WINDOW_ROWS), search_window // 2)
        if sum((h1 - h0) * (wb - wa) for _, h0, h1, wa, wb in windows) < 0.8 * bsz * h * w:
            bands = windows
        only = np.ascontiguousarray(where, dtype=np.uint8)
    nc, nb = max(1, cp.shape[1]), float(block_size * block_size)
    consts = np.array([[rb / nc, rb / (nc * nb), 1.0 / nb, 1.0, 0.0] for rb in rho.detach().cpu().double().tolist()],
                      dtype=xp.dtype)

    packed = xp.dtype == np.float32

    def band(n: int) -> None:  # a band writes only its own pixels: the bands run in any order
        b, h0, h1, wa, wb = bands[n]
        keys = np.empty((h1 - h0, k, wb - wa), np.uint64) if packed else None
        _band(xp[b], tp[b], cp[b], use_t, h, w, r, big_r, order, both, consts[b], h0, h1, wa, wb, topd[b, h0:h1],
              topi[b, h0:h1], seeded, *out_of(b), keys, None if masks is None else masks[b], only[b])

    run_tasks(band, len(bands))


# a masked search's bands: rows, and the gap (px) below which two windows of a band are searched as one. On a moving
# 640x480 stream's fresh pixels 8-32 rows and gaps of 8-64 px all took 20-22 ms
# (docs/measurements/issue28-stream/twenty-ninth-stop/masked_search_windows.txt)
_WINDOW_ROWS = 16
_WINDOW_GAP = 32


def _windows(where: np.ndarray, rows: int, reach: int) -> list[tuple[int, int, int, int, int]]:
    """The bands ``(b, h0, h1, wa, wb)`` of a masked search: in each band of ``rows`` rows that has pixels of
    ``where`` (B, H, W) bool, the runs of their columns, each widened by ``reach`` (the search radius) on both sides
    and clipped to the image, runs closer than ``_WINDOW_GAP`` joined, the rows trimmed to those of its pixels."""
    bsz, h, w = where.shape
    out = []
    for b in range(bsz):
        for h0 in range(0, h, rows):
            part = where[b, h0:h0 + rows]
            cols = np.flatnonzero(part.any(0))
            if cols.size == 0:
                continue
            breaks = np.flatnonzero(np.diff(cols) > 2 * reach + _WINDOW_GAP)
            for first, last in zip(np.r_[0, breaks + 1], np.r_[breaks, cols.size - 1]):
                wa, wb = max(0, cols[first] - reach), min(w, cols[last] + 1 + reach)
                lines = np.flatnonzero(part[:, cols[first]:cols[last] + 1].any(1))
                out.append((b, h0 + int(lines[0]), h0 + int(lines[-1]) + 1, int(wa), int(wb)))
    return out


def block_match_cpu_exact_at(depth: torch.Tensor, rgb: Optional[torch.Tensor], trust: Optional[torch.Tensor],
                             where: torch.Tensor, dist: torch.Tensor, index: torch.Tensor, block_size: int,
                             search_window: int, k: int, rho: torch.Tensor, include_self: bool) -> None:
    """The exact top-k matches of the pixels ``where`` (B, 1, H, W) bool, written into ``dist`` and ``index``
    (B, k, H, W; CPU, C-contiguous, ``dist`` of the planes' dtype) in place; the other pixels keep theirs. Each
    written pixel's matches are the whole image's search's, bit for bit: its window's rows and sums are the whole
    image's."""
    bsz, _, h, w = depth.shape
    planes = padded_planes(depth, rgb, trust, block_size // 2, search_window // 2)
    search(planes, h, w, block_size, search_window, rho, include_self, None, 1, None, None, False,
           out=(dist.detach().numpy(), index.numpy()), where=where.detach().reshape(bsz, h, w).numpy())


def block_match_cpu_exact(depth: torch.Tensor, rgb: Optional[torch.Tensor], trust: Optional[torch.Tensor],
                          block_size: int, search_window: int, k: int, rho: torch.Tensor, include_self: bool,
                          chunk_rows: Optional[int], stride: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Exact top-k block matches ``(dist, index)``, each (B, k, H, W), by the numba kernel."""
    bsz, _, h, w = depth.shape
    planes = padded_planes(depth, rgb, trust, block_size // 2, search_window // 2)
    dist = np.empty((bsz, k, h, w), dtype=planes[0].dtype)
    index = np.empty((bsz, k, h, w), dtype=np.int64)
    search(planes, h, w, block_size, search_window, rho, include_self, chunk_rows, stride, None, None, False,
           out=(dist, index))
    return torch.from_numpy(dist).to(depth.dtype), torch.from_numpy(index)
