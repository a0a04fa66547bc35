"""Approximate block matching on the CPU (numba): re-rank a few candidates per pixel exactly.

Candidates of pixel ``p`` are offsets ``o`` (so the block at ``p + o``): the offsets of ``p``'s own
previous matches and those of its neighbours' previous matches (the coherence PatchMatch exploits:
the neighbour of a good match is a good match for the neighbour). Each distinct candidate's distance
is computed directly over the block (same formula as the exact search) and kept in a sorted top-k.

In small windows the exact search's kernel runs instead, with each pixel's candidates as a bit mask over the window's
offsets (:func:`_candidate_masks`): it computes every offset's distance by box sums, which costs less there than
reaching each candidate's block alone, and keeps only the candidates' (the same lists up to the last bit of a
distance: the sums run in another order).
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import torch
from numba import njit, prange

from ..native import kernel_threads, run_range
from ._common import offset_order
from .cpu_exact import _ID_NONE, finalize, padded_planes, search

__all__ = ["refine_cpu"]

# windows up to this side re-rank by the exact search restricted to each pixel's candidates (bit masks): at 640×480,
# 2 threads, k = 10 with the step-2 lattice, 7×7: 155 -> 87 ms, 9×9: 149 -> 101 ms, 11×11: 138 -> 127 ms, 15×15:
# 217 -> 309 ms (the 48 to 224 offsets of the window for the same 10-18 candidates)
_MASKED_UP_TO = 9
_FLOOR_SHIFT = 1 << 20  # floor(x) = int(x + shift) - shift for x > -shift: a truncation of a positive number


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


@njit(cache=True, inline="always")
def _source(src, reach):
    """The pixel whose previous matches source ``src`` offers, relative to the re-ranked pixel: itself (0) or its
    neighbour ``reach`` away (1-4: up, down, left, right)."""
    if src == 1:
        return -reach, 0
    if src == 2:
        return reach, 0
    if src == 3:
        return 0, -reach
    if src == 4:
        return 0, reach
    return 0, 0


@njit(cache=True, inline="always")
def _match_offset(d, big_w, big_r, inv_w):
    """``(dy, dx)`` of a match ``d = dy·W + dx`` flat positions from its pixel (``|dx| <= R``): ``dy`` by a float
    floor, exact here (the fraction stays 0.5 / W or more away from an integer), and no libm call or integer
    division by the runtime width (that division cost about a tenth of the re-ranking)."""
    dy = np.int64((d + big_r + 0.5) * inv_w + _FLOOR_SHIFT) - np.int64(_FLOOR_SHIFT)
    return dy, d - dy * big_w


@njit(cache=True, nogil=True)
def _candidate_masks(prev, reach, base, big_h, big_w, big_r, masks, n0, n1):
    """``masks[b, o // 64, i, j]`` bit ``o % 64`` set for each offset ``o`` that pixel ``(i, j)`` re-ranks: those of
    :func:`_candidates` (its previous matches, its neighbours' at ``reach``) and those set in ``base`` (words,): the
    lattice's; for the rows ``[n0, n1)`` of the flattened (B·H) batch. Offsets whose candidate lies outside the image
    or at the centre may be set too: the search never offers those (its order omits the centre unless
    ``include_self``)."""
    s = 2 * big_r + 1
    one, zero = np.uint64(1), np.uint64(0)
    inv_w = 1.0 / big_w
    for n in range(n0, n1):
        b = n // big_h
        i = n % big_h
        mb = masks[b]
        for wd in range(mb.shape[0]):
            row = mb[wd, i]
            for j in range(big_w):
                row[j] = base[wd]
        pb = prev[b]
        for src in range(5 if reach > 0 else 1):
            di, dj = _source(src, reach)
            ni = i + di
            if ni < 0 or ni >= big_h:
                continue
            j0, j1 = max(0, -dj), min(big_w, big_w - dj)
            for m in range(pb.shape[0]):
                pm = pb[m, ni, j0 + dj:j1 + dj]
                base_flat = ni * big_w + j0 + dj
                for wd in range(mb.shape[0]):  # branch-free loops over the row (vectorised), a word at a time
                    row = mb[wd, i, j0:j1]
                    for j in range(j1 - j0):
                        flat = pm[j]
                        dy, dx = _match_offset(flat - (base_flat + j), big_w, big_r, inv_w)
                        oid = (dy + big_r) * s + dx + big_r
                        # a missing match (a stream's crop: -1) or one outside the window sets no bit
                        ok = (flat >= 0) & (abs(dy) <= big_r) & (abs(dx) <= big_r) & ((oid >> 6) == wd)
                        row[j] |= (one << np.uint64(oid & 63)) if ok else zero


def _lattice_words(search_window: int, lattice: int, words: int) -> np.ndarray:
    """The bits of the window's offsets whose ``dy`` and ``dx`` are multiples of ``lattice`` (none for 0)."""
    out = np.zeros(words, np.uint64)
    if lattice > 0:
        for oid in offset_order(search_window, lattice, True).tolist():
            out[oid >> 6] |= np.uint64(1) << np.uint64(oid & 63)
    return out


@njit(cache=True, inline="always")
def _candidates(pb, i, j, src, reach, big_h, big_w, big_r, include_self, ti, oids):
    """The offsets of source ``src`` that pixel ``(i, j)`` re-ranks, into ``oids``; returns how many: the previous
    matches of the pixel itself (``src`` 0) or of its neighbour ``reach`` away (1-4: up, down, left, right), inside
    the image, not the centre unless ``include_self``, and (a neighbour's) not already in the list ``ti[j]``. A
    source's offsets are distinct, so none of them is listed by another of the same source."""
    di, dj = _source(src, reach)
    ni, nj = i + di, j + dj
    if ni < 0 or ni >= big_h or nj < 0 or nj >= big_w:
        return 0
    s = 2 * big_r + 1
    centre = big_r * s + big_r
    inv_w = 1.0 / big_w
    n = 0
    for m in range(pb.shape[0]):
        flat = pb[m, ni, nj]
        if flat < 0:  # a missing match (a stream's crop); a neighbour's once became an offset outside the window
            continue
        dy, dx = _match_offset(flat - (ni * big_w + nj), big_w, big_r, inv_w)
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
    inv_s = 1.0 / s
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
                    oy = np.int64((oid + 0.5) * inv_s)  # oid // s (oid >= 0), without the division
                    d = _block_distance(cx, ct, cc, xb, tb, cb, use_t, i + oy, j + oid - oy * s, bs, crho, inb)
                    _offer(d, oid, td, ti, j)


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
    kernel_threads()
    if search_window <= _MASKED_UP_TO:  # the exact search, each pixel keeping its candidates only
        words = -(-search_window ** 2 // 64)
        masks = np.empty((bsz, words, h, w), np.uint64)
        base = _lattice_words(search_window, lattice, words)
        run_range(lambda n0, n1: _candidate_masks(prev, int(reach), base, h, w, big_r, masks, n0, n1), bsz * h)
        dist = np.empty((bsz, k, h, w), dtype=xp.dtype)
        index = np.empty((bsz, k, h, w), dtype=np.int64)
        search(planes, h, w, block_size, search_window, rho, include_self, None, 1, None, None, False,
               out=(dist, index), masks=masks)
        return torch.from_numpy(dist).to(depth.dtype), torch.from_numpy(index)
    topd = np.empty((bsz, h, w, k), dtype=xp.dtype)
    topi = np.empty((bsz, h, w, k), dtype=np.int32)
    nc, nb = max(1, cp.shape[1]), float(block_size * block_size)
    consts = np.array([[rb / (nc * nb), 1.0 / nb] for rb in rho.detach().cpu().double().tolist()], dtype=xp.dtype)
    _refine(xp, tp, cp, use_t, h, w, r, big_r, prev, int(reach), bool(include_self), consts, topd, topi)
    if lattice > 0:
        search(planes, h, w, block_size, search_window, rho, include_self, None, lattice, topd, topi, True)
    dist, index = finalize(topd, topi, search_window)
    return dist.to(depth.dtype), index
