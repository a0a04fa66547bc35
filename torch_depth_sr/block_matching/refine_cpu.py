"""Approximate block matching on the CPU (numba): re-rank a few candidates per pixel exactly.

Candidates of pixel ``p`` are offsets ``o`` (so the block at ``p + o``): the offsets of ``p``'s own
previous matches and those of its neighbours' previous matches (the coherence PatchMatch exploits:
the neighbour of a good match is a good match for the neighbour). Each distinct candidate's distance
is computed directly over the block (same formula as the exact search) and kept in a sorted top-k. In small windows
the distances of every offset are computed first, a vector loop per row and offset pair, and the candidates read
theirs: the same sums in the same order, so the same lists, bit for bit.
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import torch
from numba import njit, prange

from ..native import kernel_threads, run_tasks
from .cpu_exact import _ID_NONE, finalize, padded_planes, search

__all__ = ["refine_cpu"]

_BAND_ROWS = 16  # rows per task of the re-ranking
# windows up to this side compute every offset's distance for every pixel (vector loops) rather than each candidate's
# alone: at 7×7 (48 offsets, 24 by symmetry, for 10 candidates) 640×480, one thread, refine_matches with its lattice
# 335-587 -> 237-303 ms; a 21×21 window has 440 offsets for the same 10 candidates
_PLANES_UP_TO = 9


# The pixel-major top-k list of the re-ranking (the exact search keeps rank-major lists). Kept in this file with
# _refine, which inlines them: numba's disk cache of _refine is invalidated only by a change of this file.
@njit(cache=True, inline="always")
def _offer(d, oid, td, ti, j):
    """Insert ``(d, oid)`` into the sorted list ``td[j], ti[j]`` of length k if it beats the last entry."""
    k = td.shape[1]
    if d > td[j, k - 1] or (d == td[j, k - 1] and oid >= ti[j, k - 1]):
        return
    m = k - 1
    while m > 0 and (td[j, m - 1] > d or (td[j, m - 1] == d and ti[j, m - 1] > oid)):
        td[j, m] = td[j, m - 1]
        ti[j, m] = ti[j, m - 1]
        m -= 1
    td[j, m] = d
    ti[j, m] = oid


@njit(cache=True, inline="always")
def _listed(oid, ti, j):
    """Whether offset ``oid`` is already in the list ``ti[j]`` (lists seeded with other candidates)."""
    for m in range(ti.shape[1]):
        if ti[j, m] == oid:
            return True
    return False


@njit(cache=True, inline="always")
def _block_distance(cx, ct, cc, xp, tp, cp, use_t, yb, xb, bs, crho, inb):
    """d(i, j) between the block held in ``cx, ct`` (bs, bs) and ``cc`` (C, bs, bs), pixel i's, and the block whose
    top-left corner is (yb, xb) in the padded planes; the sums in the order of the block's rows, then columns.

    Accumulates in the planes' dtype (float32 stays float32, like the exact kernel); ``crho``, ``inb`` too. The
    candidate's indices are unsigned: numba tests a signed index for a negative value at every access.
    """
    zero = cx[0, 0] - cx[0, 0]
    num = zero
    cnt = zero
    col = zero
    x0 = np.uint64(xb)
    for u in range(bs):
        xb_row = xp[np.uint64(yb + u)]
        tb_row = tp[np.uint64(yb + u)]
        for v in range(bs):
            df = cx[u, v] - xb_row[x0 + np.uint64(v)]
            if use_t:
                tt = ct[u, v] * tb_row[x0 + np.uint64(v)]
                num += tt * (df * df)
                cnt += tt
            else:
                num += df * df
    for c in range(cp.shape[0]):
        for u in range(bs):
            cb = cp[c, np.uint64(yb + u)]
            for v in range(bs):
                dc = cc[c, u, v] - cb[x0 + np.uint64(v)]
                col += dc * dc
    one = zero + 1
    d = num / max(cnt, one) if use_t else num * inb
    d += crho * col
    return d if d > zero else zero


@njit(cache=True, nogil=True, error_model="numpy")
def _distance_row(xb, tb, cb, use_t, big_w, r, big_r, i, dy, dx, crho, inb, out, num, cnt, col):
    """:func:`_block_distance` of every pixel ``(i, j)`` of row ``i`` whose candidate ``(i + dy, j + dx)`` lies in the
    image (``dy >= 0``), into ``out[j]``: the same sums in the same order (the block's rows, then columns, then the
    channels), each a vector loop over the row's pixels."""
    bs = 2 * r + 1
    j0 = max(0, -dx)
    j1 = min(big_w, big_w - dx)
    n = j1 - j0
    if n <= 0:
        return
    zero = xb[0, 0] - xb[0, 0]
    nu = num[:n]
    ct = cnt[:n]
    co = col[:n]
    for j in range(n):
        nu[j] = zero
        ct[j] = zero
        co[j] = zero
    for u in range(bs):
        xa = xb[big_r + i + u, big_r + j0:big_r + j1 + bs - 1]
        xc = xb[big_r + i + dy + u, big_r + j0 + dx:big_r + j1 + dx + bs - 1]
        ta = tb[big_r + i + u, big_r + j0:big_r + j1 + bs - 1]
        tc = tb[big_r + i + dy + u, big_r + j0 + dx:big_r + j1 + dx + bs - 1]
        for v in range(bs):
            if use_t:
                for j in range(n):
                    df = xa[j + v] - xc[j + v]
                    tt = ta[j + v] * tc[j + v]
                    nu[j] += tt * (df * df)
                    ct[j] += tt
            else:
                for j in range(n):
                    df = xa[j + v] - xc[j + v]
                    nu[j] += df * df
    for c in range(cb.shape[0]):
        for u in range(bs):
            ca = cb[c, big_r + i + u, big_r + j0:big_r + j1 + bs - 1]
            cc = cb[c, big_r + i + dy + u, big_r + j0 + dx:big_r + j1 + dx + bs - 1]
            for v in range(bs):
                for j in range(n):
                    dc = ca[j + v] - cc[j + v]
                    co[j] += dc * dc
    one = zero + 1
    o = out[j0:j1]
    for j in range(n):
        d = nu[j] / max(ct[j], one) if use_t else nu[j] * inb
        d += crho * co[j]
        o[j] = d if d > zero else zero


@njit(cache=True, nogil=True, error_model="numpy")
def _offset_planes(xb, tb, cb, use_t, big_h, big_w, r, big_r, include_self, crho, inb, h0, h1, planes):
    """``planes[o, i - h0, j]`` = the distance of pixel ``(i, j)`` to its candidate at offset ``o``, for the rows
    ``[h0, h1)`` and every offset ``o`` of the window whose candidate lies in the image (other entries unwritten).
    Called from a serial kernel (:func:`_refine_band`): in a parallel loop's body numba turned each slice copy into a
    parallel loop of its own and compiled 7 s longer per dtype, for 20-30 % less time."""
    s = 2 * big_r + 1
    centre = big_r * s + big_r
    num = np.empty(big_w, xb.dtype)
    cnt = np.empty(big_w, xb.dtype)
    col = np.empty(big_w, xb.dtype)
    row = np.empty(big_w, np.float64)
    for oid in range(centre, s * s):  # the centre and the offsets after it: (dy, dx) > (0, 0)
        if oid == centre and not include_self:
            continue
        dy = oid // s - big_r
        dx = oid % s - big_r
        mid = 2 * centre - oid  # the mirrored offset (-dy, -dx)
        # d(p, p + o) = d(p + o, p), bit for bit (the same products and squares, summed in the same order): a row i
        # gives pixel (i, j) its offset o and pixel (i + dy, j + dx) its offset -o
        j0 = max(0, -dx)
        j1 = min(big_w, big_w - dx)
        for i in range(max(0, h0 - dy), min(h1, big_h - dy)):
            _distance_row(xb, tb, cb, use_t, big_w, r, big_r, i, dy, dx, crho, inb, row, num, cnt, col)
            if i >= h0:
                out = planes[oid, i - h0]
                for j in range(j0, j1):
                    out[j] = row[j]
            if h0 <= i + dy < h1 and oid != centre:
                out = planes[mid, i + dy - h0]
                for j in range(j0, j1):
                    out[j + dx] = row[j]


@njit(cache=True, inline="always")
def _candidates(pb, i, j, src, reach, big_h, big_w, big_r, include_self, ti, oids):
    """The offsets of source ``src`` that pixel ``(i, j)`` re-ranks, into ``oids``; returns how many: the previous
    matches of the pixel itself (``src`` 0) or of its neighbour ``reach`` away (1-4: up, down, left, right), inside
    the image, not the centre unless ``include_self``, and (a neighbour's) not already in the list ``ti[j]``. A
    source's offsets are distinct, so none of them is listed by another of the same source."""
    ni, nj = i, j
    if src == 1:
        ni = i - reach
    elif src == 2:
        ni = i + reach
    elif src == 3:
        nj = j - reach
    elif src == 4:
        nj = j + reach
    if ni < 0 or ni >= big_h or nj < 0 or nj >= big_w:
        return 0
    s = 2 * big_r + 1
    centre = big_r * s + big_r
    n = 0
    for m in range(pb.shape[0]):
        flat = pb[m, ni, nj]
        dy = flat // big_w - ni
        dx = flat % big_w - nj
        oid = (dy + big_r) * s + dx + big_r
        if oid == centre and not include_self:
            continue
        if i + dy < 0 or i + dy >= big_h or j + dx < 0 or j + dx >= big_w:
            continue
        if src > 0 and _listed(oid, ti, j):
            continue
        oids[n] = oid
        n += 1
    return n


# parallel=True (numba.prange), unlike the other kernels (nogil functions run by native.run_tasks): as a serial nogil
# function this body ran 20-30 % slower on one thread, even with error_model="numpy" (docs/measurements/
# numba-first-use/; numba compiles a prange body with noalias array arguments, the likely reason). That is worth the
# 2-3 s of CPU that the parallel form adds to the first compilation.
@njit(cache=True, parallel=True)
def _refine(xp, tp, cp, use_t, big_h, big_w, r, big_r, prev, reach, include_self, consts, topd, topi):
    """prev: (B, kp, H, W) flat indices of the previous matches; reach: neighbour distance (0 = none). Each
    candidate's distance computed alone (:func:`_block_distance`)."""
    bsz = xp.shape[0]
    bs = 2 * r + 1
    s = 2 * big_r + 1
    for n in prange(bsz * big_h):
        b = n // big_h
        i = n % big_h
        crho = consts[b, 0]
        inb = consts[b, 1]
        xb, tb, cb = xp[b], tp[b], cp[b]  # views made once per row: inside the pixel loop they would cost
        td = topd[b, i]
        ti = topi[b, i]
        pb = prev[b]
        cx = np.empty((bs, bs), xp.dtype)  # pixel i's block, read once for all its candidates
        ct = np.empty((bs, bs), xp.dtype)
        cc = np.empty((cp.shape[1], bs, bs), xp.dtype)
        oids = np.empty(prev.shape[1], np.int64)
        for j in range(big_w):
            for u in range(bs):
                for v in range(bs):
                    cx[u, v] = xb[big_r + i + u, big_r + j + v]
                    if use_t:
                        ct[u, v] = tb[big_r + i + u, big_r + j + v]
                    for c in range(cp.shape[1]):
                        cc[c, u, v] = cb[c, big_r + i + u, big_r + j + v]
            for m in range(td.shape[1]):
                td[j, m] = np.inf
                ti[j, m] = _ID_NONE
            for src in range(5 if reach > 0 else 1):
                for q in range(_candidates(pb, i, j, src, reach, big_h, big_w, big_r, include_self, ti, oids)):
                    oid = oids[q]
                    d = _block_distance(cx, ct, cc, xb, tb, cb, use_t, big_r + i + oid // s - big_r,
                                        big_r + j + oid % s - big_r, bs, crho, inb)
                    _offer(d, oid, td, ti, j)


@njit(cache=True, nogil=True)
def _refine_band(xp, tp, cp, use_t, big_h, big_w, r, big_r, prev, reach, include_self, consts, topd, topi, n, band):
    """:func:`_refine` for the ``n``-th band of ``band`` rows of the flattened batch, reading each candidate's
    distance from the band's planes of every offset (:func:`_offset_planes`): the same distances, in float64 as
    :func:`_block_distance` returns them, compared so with the lists."""
    s = 2 * big_r + 1
    nbands = (big_h + band - 1) // band
    b = n // nbands
    h0 = (n % nbands) * band
    h1 = min(big_h, h0 + band)
    planes = np.empty((s * s, h1 - h0, big_w), np.float64)
    _offset_planes(xp[b], tp[b], cp[b], use_t, big_h, big_w, r, big_r, include_self, consts[b, 0], consts[b, 1], h0,
                   h1, planes)
    pb = prev[b]
    oids = np.empty(prev.shape[1], np.int64)
    for i in range(h0, h1):
        td = topd[b, i]
        ti = topi[b, i]
        pl = planes[:, i - h0]
        for j in range(big_w):
            for m in range(td.shape[1]):
                td[j, m] = np.inf
                ti[j, m] = _ID_NONE
            for src in range(5 if reach > 0 else 1):
                for q in range(_candidates(pb, i, j, src, reach, big_h, big_w, big_r, include_self, ti, oids)):
                    _offer(pl[oids[q], j], oids[q], td, ti, j)


def refine_cpu(depth: torch.Tensor, rgb: Optional[torch.Tensor], trust: Optional[torch.Tensor],
               previous_index: torch.Tensor, block_size: int, search_window: int, k: int, rho: torch.Tensor,
               include_self: bool, reach: int, lattice: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Top-k ``(dist, index)`` among the previous matches of each pixel and of its 4 neighbours at ``reach``,
    and (``lattice > 0``) the offsets of the search window on a lattice of that step."""
    bsz, _, h, w = depth.shape
    r, big_r = block_size // 2, search_window // 2
    planes = padded_planes(depth, rgb, trust, r, big_r)  # shared by the re-scoring and the lattice search
    xp, tp, cp, use_t = planes
    prev = previous_index.detach().cpu().to(torch.int64).contiguous().numpy()  # int64, C order: one compiled signature
    topd = np.empty((bsz, h, w, k), dtype=xp.dtype)
    topi = np.empty((bsz, h, w, k), dtype=np.int32)
    nc, nb = max(1, cp.shape[1]), float(block_size * block_size)
    consts = np.array([[rb / (nc * nb), 1.0 / nb] for rb in rho.detach().cpu().double().tolist()], dtype=xp.dtype)
    kernel_threads()
    if search_window <= _PLANES_UP_TO:  # bands of rows on torch's threads (the kernel releases the GIL)
        bands = bsz * -(-h // _BAND_ROWS)
        run_tasks(lambda n: _refine_band(xp, tp, cp, use_t, h, w, r, big_r, prev, int(reach), bool(include_self),
                                         consts, topd, topi, n, _BAND_ROWS), bands)
    else:
        _refine(xp, tp, cp, use_t, h, w, r, big_r, prev, int(reach), bool(include_self), consts, topd, topi)
    if lattice > 0:
        search(planes, h, w, block_size, search_window, rho, include_self, None, lattice, topd, topi, True)
    dist, index = finalize(topd, topi, search_window)
    return dist.to(depth.dtype), index
