"""The running top-k lists of a band of image rows, rank-major: the lists of a row are ``(k, W)`` arrays, rank ``m`` of
every pixel of the row contiguous, so that offering a row of candidate distances (one offset of the search window,
``cpu_exact._band``) is a few vector loops. Keys compare as ``(distance, offset id)``; a list is sorted by key, and a
key enters it when it sorts before the k-th. Compiled by LLVM at first use and cached on disk (``cache=True``).
"""
from __future__ import annotations

from numba import njit

__all__ = ["offer_row"]


@njit(cache=True, inline="always")
def _beats(d, oid, e, eid):
    """Whether key ``(d, oid)`` sorts before ``(e, eid)``."""
    return d < e or (d == e and oid < eid)


@njit(cache=True, nogil=True)
def _count_beating(dv, last_d, last_i, oid):
    """How many of ``dv[j]`` (with id ``oid``) beat the k-th entries ``last_d[j], last_i[j]`` (a vector loop)."""
    n = 0
    for j in range(dv.shape[0]):
        d = dv[j]
        e = last_d[j]
        n += (d < e) | ((d == e) & (oid < last_i[j]))
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
        above = (d < p) | ((d == p) & (oid < p_id))
        here = (d < c) | ((d == c) & (oid < c_id))
        cd[j] = p if above else (d if here else c)
        ci[j] = p_id if above else (oid if here else c_id)


@njit(cache=True, nogil=True)
def _merge_first(dv, cd, ci, oid):
    """Rank 0 of every column after offering ``dv``."""
    for j in range(dv.shape[0]):
        d = dv[j]
        c = cd[j]
        c_id = ci[j]
        here = (d < c) | ((d == c) & (oid < c_id))
        cd[j] = d if here else c
        ci[j] = oid if here else c_id


@njit(cache=True, nogil=True)
def offer_row(dd, j0, j1, a0, oid, rd, ri, seeded):
    """Offer the distances ``dd[j0:j1]`` (id ``oid``) to the rank-major lists ``rd, ri`` (k, W) of the columns
    ``a0 ...``. Late offsets (most of them, nearest first) beat no list of the row: one vector count skips them.
    Early ones beat many: with a short list, every rank is rewritten by a branch-free vector loop; otherwise,
    and for few insertions, one column at a time. At 640x480 on one thread, k = 10 of a 7x7 window: 0.27-0.38 ->
    0.12-0.16 s for the whole search (the pixel-major lists tested and inserted pixel by pixel); k = 40 of 15x15:
    no change beyond the noise (1.8-2.4 s either way), whichever split of the two ways."""
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
