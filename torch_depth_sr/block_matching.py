"""Block matching: the ``k`` blocks most similar to the block around every pixel (paper eq. 2-4).

For every pixel ``i`` the ``b×b`` block ``P_i`` around it is compared with the blocks ``P_j`` around
every pixel ``j = i + o`` of an ``S×S`` search window (offsets ``o = (dy, dx)``, ``|dy|, |dx| ≤ S//2``):

.. math::

    d(i, j) = \\frac{\\sum_{p} t_i(p)\\, t_j(p)\\, (x_i(p) - x_j(p))^2}{\\max(1, \\sum_p t_i(p)\\, t_j(p))}
              + \\rho \\, \\operatorname{mean}_{p, c}\\, (c_i(p) - c_j(p))^2

where ``x`` is the depth, ``t`` the trust mask (1 = trusted) and ``c`` the colour guide. Both terms
are means over the block, so the units are "per pixel". Block pixels outside the image are
replicate-padded; candidate centres ``j`` outside the image are never selected. The ``k`` smallest
distances are kept, sorted ascending; ties are broken by the smaller offset id
``(dy + S//2)·S + (dx + S//2)`` (row-major over the window) in both implementations. The weights are
``ω_ij = softmax_j(−d(i, j) / h)`` over the kept blocks.

Two implementations give the same result:

* :func:`block_match_reference` — ``F.unfold`` of every candidate block; readable, obviously correct,
  memory ``O(b²·S²·H·W)``: for small images and tests.
* :func:`block_match` — the default. Shift-and-box-filter: the squared-difference images of the
  offsets are box-summed over the block and the ``k`` smallest kept. On CPU a small C kernel walks
  the offsets with a running top-``k`` (numpy/OpenCV fallback: one window row ``dy`` at a time); on
  other devices (torch) every offset of a band of rows is formed at once (``as_strided`` views,
  ``avg_pool2d``) and one selection per pixel keeps the ``k`` smallest — few, large launches suit a
  GPU. The offset id is packed into the low bits of the distance's float64 bit pattern (a float32
  distance has 29 unused low bits there), so one integer selection picks distance and index
  together, without an argsort. Rows are processed in chunks, so memory stays bounded (tens of MB
  per CPU thread; about 2 GB on a GPU at any image size).

Reference: Y. Yang et al., "depth maps restoration based on the sparse representation of nonlocal
self-similarity" (the paper under ``shared/paper``), §II-B.
"""
from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple, Optional, Union

import numpy as np
import torch
import torch.nn.functional as F

from ._checks import check_4d, check_floating, check_same_hw
from .errors import DepthSRError, ShapeError

__all__ = ["BlockMatches", "block_match", "block_match_reference", "gather_neighbors"]

Scalar = Union[float, torch.Tensor]

_INT64_MAX = np.iinfo(np.int64).max


class BlockMatches(NamedTuple):
    """Result of block matching, sorted ascending by distance along dim 1.

    If ``index[b, m, i, j] = p`` then the block centred at pixel ``p`` (flat index ``y * W + x``)
    is the ``m``-th most similar block to the block centred at ``(i, j)`` in sample ``b``.

    Attributes:
        dist: ``(B, k, H, W)`` block distances ``d(i, j)`` (no gradient), ascending in ``k``.
        index: ``(B, k, H, W)`` int64 flat indices of the matched block centres (no gradient).
        weight: ``(B, k, H, W)`` ``softmax(−dist / temperature)`` over ``k``; sums to 1. It carries a
            gradient to ``temperature`` when that is a tensor requiring grad, never to the images.
    """

    dist: torch.Tensor
    index: torch.Tensor
    weight: torch.Tensor


# ----------------------------------------------------------------------------------------------
# validation
# ----------------------------------------------------------------------------------------------


def _lattice(radius: int, stride: int) -> list[int]:
    """Offsets ``-radius..radius`` that are multiples of ``stride`` (0 always included)."""
    return [o for o in range(-radius, radius + 1) if o % stride == 0]


def _min_valid_offsets(size: int, radius: int, stride: int) -> int:
    """Smallest number of in-image lattice offsets along one axis, over all positions."""
    offs = np.array(_lattice(radius, stride))
    pos = np.arange(size)[:, None] + offs[None, :]
    return int(((pos >= 0) & (pos < size)).sum(1).min())


def _per_sample(value: Scalar, name: str, batch: int, positive: bool) -> torch.Tensor:
    """A float or (B,)/(1,)/() tensor as a (B,) tensor; checks the sign."""
    if isinstance(value, torch.Tensor):
        if value.ndim > 1 or (value.ndim == 1 and value.numel() not in (1, batch)):
            raise ShapeError(f"{name} must be a float or a tensor of shape ({batch},) or (); got shape "
                             f"{tuple(value.shape)}.")
        v = value.reshape(-1).expand(batch) if value.numel() == 1 else value.reshape(batch)
    else:
        try:
            v = torch.full((batch,), float(value), dtype=torch.float64)
        except (TypeError, ValueError):
            raise DepthSRError(f"{name} must be a float or a (B,) tensor; got {type(value).__name__}.") from None
    vd = v.detach()
    bad = ~torch.isfinite(vd) | ((vd <= 0) if positive else (vd < 0))
    if bool(bad.any()):
        rule = "> 0" if positive else ">= 0"
        raise DepthSRError(f"{name} must be finite and {rule}; got {vd.tolist()}.")
    return v


def _validate(depth, rgb, trust, block_size, search_window, k, search_stride):
    check_4d(depth, "depth", channels=1)
    check_floating(depth, "depth")
    if rgb is not None:
        check_4d(rgb, "rgb")
        if rgb.shape[1] < 1:
            raise ShapeError(f"rgb must have at least one channel; got shape {tuple(rgb.shape)}.")
        check_same_hw(depth, rgb, "depth", "rgb")
    if trust is not None:
        check_4d(trust, "trust", channels=1)
        check_same_hw(depth, trust, "depth", "trust")
    for name, v in (("block_size", block_size), ("search_window", search_window)):
        if isinstance(v, bool) or not isinstance(v, int) or v < 1 or v % 2 == 0:
            raise DepthSRError(f"{name} must be a positive odd int (the block is centred on the pixel); "
                               f"got {v!r}. Use e.g. {v + 1 if isinstance(v, int) and v > 0 else 5}.")
    if isinstance(search_stride, bool) or not isinstance(search_stride, int) or search_stride < 1:
        raise DepthSRError(f"search_stride must be an int >= 1; got {search_stride!r}.")
    if isinstance(k, bool) or not isinstance(k, int) or k < 1:
        raise DepthSRError(f"k must be an int >= 1; got {k!r}.")
    _, _, h, w = depth.shape
    if h < block_size or w < block_size:
        raise ShapeError(f"depth is {h}x{w}, smaller than one {block_size}x{block_size} block; "
                         f"the image must be at least {block_size}x{block_size}. Use a smaller block_size.")


def _check_k(k, h, w, search_window, search_stride, include_self):
    radius = search_window // 2
    n_min = _min_valid_offsets(h, radius, search_stride) * _min_valid_offsets(w, radius, search_stride)
    n_min -= 0 if include_self else 1
    if k > n_min:
        raise DepthSRError(
            f"k={k} is larger than the number of candidate blocks available at every pixel ({n_min} at the "
            f"image corner for search_window={search_window}, search_stride={search_stride}, "
            f"include_self={include_self}, image {h}x{w}). Use k <= {n_min} or a larger search_window.")


def _prepare(depth, rgb, trust, block_size, search_window, k, color_weight, temperature, include_self,
             search_stride):
    _validate(depth, rgb, trust, block_size, search_window, k, search_stride)
    b, _, h, w = depth.shape
    _check_k(k, h, w, search_window, search_stride, include_self)
    rho = _per_sample(color_weight, "color_weight", b, positive=False)
    temp = _per_sample(temperature, "temperature", b, positive=True)
    return rho, temp


def _finish(dist, index, temp):
    """Weights = softmax(−dist/h) over k (differentiable in a tensor temperature)."""
    t = temp.to(device=dist.device, dtype=dist.dtype).view(-1, 1, 1, 1)
    weight = torch.softmax(-dist / t, dim=1)
    return BlockMatches(dist, index, weight)


def _index_from_offsets(oid: torch.Tensor, search_window: int, h: int, w: int) -> torch.Tensor:
    """Offset ids ``(dy+R)·S + (dx+R)`` at pixel (i, j) → flat index ``(i+dy)·W + (j+dx)`` (int64).

    Uses a lookup table ``dy·W + dx`` and one in-place add, so the only large allocation is the result.
    """
    r = search_window // 2
    offs = torch.arange(-r, r + 1, device=oid.device)
    lut = (offs.view(-1, 1) * w + offs.view(1, -1)).reshape(-1)  # (S²,) int64
    index = lut[oid.long()]  # (B, k, H, W)
    index += torch.arange(h * w, device=oid.device).view(1, 1, h, w)
    return index


# ----------------------------------------------------------------------------------------------
# reference
# ----------------------------------------------------------------------------------------------


def block_match_reference(
    depth: torch.Tensor,
    rgb: Optional[torch.Tensor] = None,
    trust: Optional[torch.Tensor] = None,
    block_size: int = 5,
    search_window: int = 21,
    k: int = 10,
    color_weight: Scalar = 1.0,
    temperature: Scalar = 1.0,
    include_self: bool = False,
    chunk_rows: Optional[int] = None,
    *,
    search_stride: int = 1,
) -> BlockMatches:
    """Block matching by ``F.unfold`` of every candidate block: slow, memory hungry, obviously correct.

    Same arguments and result as :func:`block_match` (``chunk_rows`` is accepted and ignored). Memory is
    ``O(C·b²·S²·H·W)``: use it on small images (tests), never on full frames.

    Examples:
        >>> x = torch.rand(1, 1, 12, 12)
        >>> m = block_match_reference(x, None, None, block_size=3, search_window=5, k=4)
        >>> m.index.shape
        torch.Size([1, 4, 12, 12])
    """
    rho, temp = _prepare(depth, rgb, trust, block_size, search_window, k, color_weight, temperature,
                         include_self, search_stride)
    bsz, _, h, w = depth.shape
    r, big_r = block_size // 2, search_window // 2
    nb, ns = block_size * block_size, search_window * search_window

    def blocks(img):  # (B,C,H,W) -> (B, C, b², 1, H, W): the block around every pixel
        c = img.shape[1]
        p = F.unfold(F.pad(img, (r, r, r, r), mode="replicate"), block_size)  # (B, C·b², H·W)
        return p.view(bsz, c, nb, 1, h, w)

    def candidates(blk):  # (B, C, b², 1, H, W) -> (B, C, b², S², H, W): block at i + offset, 0 outside
        c = blk.shape[1]
        u = F.unfold(blk.reshape(bsz, c * nb, h, w), search_window, padding=big_r)  # (B, C·b²·S², H·W)
        return u.view(bsz, c, nb, ns, h, w)

    with torch.no_grad():
        x = depth.detach()
        t = torch.ones_like(x) if trust is None else trust.detach().to(x.dtype)
        xi, ti = blocks(x), blocks(t)
        xj, tj = candidates(xi), candidates(ti)
        tt = ti * tj  # (B,1,b²,S²,H,W)
        num = (tt * (xi - xj) ** 2).sum(dim=(1, 2))  # (B, S², H, W)
        cnt = tt.sum(dim=(1, 2))  # (B, S², H, W)
        dist = num / cnt.clamp_min(1.0)
        if rgb is not None:
            ci = blocks(rgb.detach().to(x.dtype))
            col = ((ci - candidates(ci)) ** 2).mean(dim=(1, 2))  # (B, S², H, W)
            dist = dist + rho.to(x).view(-1, 1, 1, 1) * col
        ones = torch.ones(1, 1, h, w, dtype=x.dtype, device=x.device)
        valid = F.unfold(ones, search_window, padding=big_r).view(1, ns, h, w) > 0  # (1, S², H, W)
        lat = torch.tensor([(o // search_window - big_r) % search_stride == 0
                            and (o % search_window - big_r) % search_stride == 0 for o in range(ns)],
                           device=x.device).view(1, ns, 1, 1)
        valid = valid & lat
        centre = ns // 2
        if include_self:
            dist[:, centre] = 0.0
        else:
            valid = valid.clone()
            valid[:, centre] = False
        dist = torch.where(valid, dist, torch.full_like(dist, math.inf))
        sd, order = torch.sort(dist, dim=1, stable=True)  # ties -> smaller offset id
        sd, order = sd[:, :k].contiguous(), order[:, :k]
        index = _index_from_offsets(order, search_window, h, w)
    return _finish(sd, index, temp)


# ----------------------------------------------------------------------------------------------
# fast path, CPU: numpy + OpenCV
# ----------------------------------------------------------------------------------------------


def _pack_keys(d: np.ndarray, oid: np.ndarray, low_mask: int) -> np.ndarray:
    """Distances (..., G) ≥ 0 and offset ids (G,) → int64 sort keys ordered by (d, oid)."""
    if d.dtype == np.float32:
        d64 = d.astype(np.float64)  # exact; the low 29 mantissa bits are zero
        keys = d64.view(np.int64)
    else:
        keys = d.view(np.int64) & ~np.int64(low_mask)  # float64: drop the low bits (rel. 2^-43)
    keys |= oid
    return keys


def _match_rows_numpy(xp, cp, tp, h0, h1, h, w, block_size, search_window, k, rho, include_self, stride):
    """Top-k keys (int64, sorted) for image rows [h0, h1) of one sample.

    ``xp`` (H+2r+2R, W+2r+2R) is the depth replicate-padded by r then zero-padded by R; ``cp`` a list
    of such colour planes (or None); ``tp`` the padded trust (or None).
    """
    import cv2

    r, big_r, s = block_size // 2, search_window // 2, search_window
    nb = float(block_size * block_size)
    rows = h1 - h0
    offs_x = np.array(_lattice(big_r, stride))
    g = len(offs_x)
    low_mask = (1 << max(1, (s * s - 1).bit_length())) - 1
    ya, yb = big_r + h0, big_r + h1 + 2 * r  # rows of the i-blocks (with halo) in padded coordinates
    xa = xp[ya:yb, big_r:big_r + w + 2 * r][:, :, None]  # (rows+2r, W+2r, 1)
    ta = None if tp is None else tp[ya:yb, big_r:big_r + w + 2 * r][:, :, None]
    ca = None if cp is None else [p[ya:yb, big_r:big_r + w + 2 * r][:, :, None] for p in cp]
    ncol = 0 if cp is None else len(cp)
    crho = rho / (ncol * nb) if ncol else 0.0
    col_valid = ((np.arange(w)[:, None] + offs_x[None, :]) >= 0) & ((np.arange(w)[:, None] + offs_x[None, :]) < w)
    top = np.full((rows * w, k), _INT64_MAX, dtype=np.int64)
    win = slice(None, None, stride)

    def box(a):  # (rows+2r, W+2r, G) -> (rows, W, G) unnormalised b×b sums
        if a.shape[2] <= 512:
            out = cv2.boxFilter(a, -1, (block_size, block_size), normalize=False,
                                borderType=cv2.BORDER_REPLICATE)
        else:
            out = np.concatenate([box_raw(a[:, :, i:i + 512]) for i in range(0, a.shape[2], 512)], axis=2)
        return out[r:r + rows, r:r + w]

    def box_raw(a):
        return cv2.boxFilter(np.ascontiguousarray(a), -1, (block_size, block_size), normalize=False,
                             borderType=cv2.BORDER_REPLICATE)

    for dy in _lattice(big_r, stride):
        lo, hi = max(0, -dy - h0), min(rows, h - dy - h0)  # chunk rows whose candidate row is inside
        if hi <= lo:
            continue
        band = slice(ya + dy, yb + dy)
        vb = np.lib.stride_tricks.sliding_window_view(xp[band], s, axis=1)[:, :, win]  # (rows+2r, W+2r, G)
        e = xa - vb
        np.square(e, out=e)
        if tp is not None:
            tt = ta * np.lib.stride_tricks.sliding_window_view(tp[band], s, axis=1)[:, :, win]
            e *= tt
        if cp is not None:
            csum = None
            for a_c, p in zip(ca, cp):
                dc = a_c - np.lib.stride_tricks.sliding_window_view(p[band], s, axis=1)[:, :, win]
                np.square(dc, out=dc)
                if csum is None:
                    csum = dc
                else:
                    csum += dc
        if tp is None:
            if cp is not None:
                e += csum * (crho * nb)  # one box sum for both terms when every pixel is trusted
            d = box(e)
            d *= 1.0 / nb
        else:
            d = box(e)
            cnt = box(tt)
            np.maximum(cnt, 1.0, out=cnt)
            d /= cnt
            if cp is not None:
                d += box(csum) * crho
        d = d[lo:hi]  # (n_rows, W, G)
        np.maximum(d, 0.0, out=d)  # running-sum round-off; also turns -0.0 into +0.0 below
        d += 0.0
        oid = ((dy + big_r) * s + offs_x + big_r).astype(np.int64)  # (G,)
        keys = _pack_keys(np.ascontiguousarray(d), oid, low_mask)  # (n_rows, W, G)
        keys[:, ~col_valid] = _INT64_MAX
        if dy == 0:
            ci = int(np.nonzero(offs_x == 0)[0][0])
            keys[:, :, ci] = oid[ci] if include_self else _INT64_MAX
        part = top[lo * w:hi * w]
        buf = np.concatenate([part, keys.reshape(-1, g)], axis=1)  # (n, k+G)
        buf.sort(axis=1)
        top[lo * w:hi * w] = buf[:, :k]
    return top


def _pad_plane(a: np.ndarray, r: int, big_r: int) -> np.ndarray:
    return np.pad(np.pad(a, r, mode="edge"), big_r, mode="constant")


def _block_match_numpy(depth, rgb, trust, block_size, search_window, k, rho, include_self, chunk_rows, stride):
    bsz, _, h, w = depth.shape
    r, big_r = block_size // 2, search_window // 2
    npdt = np.float64 if depth.dtype == torch.float64 else np.float32
    low_mask = (1 << max(1, (search_window * search_window - 1).bit_length())) - 1
    g = len(_lattice(big_r, stride))
    if chunk_rows is None:
        # ~0.6 MB per row of 640 px with G=21: keep a chunk's working set near the L2 cache size
        chunk_rows = max(4, min(h, int(24576 // max(1, w * max(g, 8) // 21))))
    jobs = []
    samples = []
    for b in range(bsz):
        x = depth[b, 0].detach().cpu().numpy().astype(npdt, copy=False)
        xp = _pad_plane(x, r, big_r)
        tp = None
        if trust is not None:
            t = trust[b, 0].detach().cpu().numpy().astype(npdt, copy=False)
            tp = _pad_plane(t, r, big_r)
        cp = None
        if rgb is not None:
            cp = [_pad_plane(rgb[b, c].detach().cpu().numpy().astype(npdt, copy=False), r, big_r)
                  for c in range(rgb.shape[1])]
        samples.append((xp, cp, tp, float(rho[b])))
        for h0 in range(0, h, chunk_rows):
            jobs.append((b, h0, min(h, h0 + chunk_rows)))

    def run(job):
        b, h0, h1 = job
        xp, cp, tp, rb = samples[b]
        return _match_rows_numpy(xp, cp, tp, h0, h1, h, w, block_size, search_window, k, rb, include_self, stride)

    workers = max(1, min(len(jobs), torch.get_num_threads(), os.cpu_count() or 1))
    if workers > 1:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            results = list(pool.map(run, jobs))
    else:
        results = [run(j) for j in jobs]
    keys = np.empty((bsz, h * w, k), dtype=np.int64)
    for (b, h0, h1), res in zip(jobs, results):
        keys[b, h0 * w:h1 * w] = res
    oid = torch.from_numpy(keys & low_mask).permute(0, 2, 1).reshape(bsz, k, h, w)
    dist = torch.from_numpy((keys & ~np.int64(low_mask)).view(np.float64))
    dist = dist.permute(0, 2, 1).reshape(bsz, k, h, w).to(depth.dtype)
    index = _index_from_offsets(oid, search_window, h, w)
    return dist.to(depth.device), index.to(depth.device)


# ----------------------------------------------------------------------------------------------
# fast path, CPU: a small C kernel (compiled once with the system C compiler, cached), if available
# ----------------------------------------------------------------------------------------------

_C_TEMPLATE = r"""
static void insert_SFX(REAL v, int32_t id, REAL* td, int32_t* ti, int k) {
    int m = k - 1;
    while (m > 0 && (td[m - 1] > v || (td[m - 1] == v && ti[m - 1] > id))) {
        td[m] = td[m - 1]; ti[m] = ti[m - 1]; --m;
    }
    td[m] = v; ti[m] = id;
}

/* Offer the distances dd[j0..j1) of one image row, under offset id `id`, to the running top-k lists
   td/ti (k entries per pixel; td, ti point at the list of column 0 of the receiving row). */
static void offer_row_SFX(const REAL* dd, int j0, int j1, int32_t id, REAL* td, int32_t* ti, int k) {
    for (int j = j0; j < j1; ++j) {
        const REAL d = dd[j];
        REAL* tdj = td + (int64_t)j * k;
        int32_t* tij = ti + (int64_t)j * k;
        if (d < tdj[k - 1] || (d == tdj[k - 1] && id < tij[k - 1])) insert_SFX(d, id, tdj, tij, k);
    }
}

/* Running top-k over the search window for image rows [h0, h1) of one sample.
   xp, tp, cp: planes padded by r (replicate) then R (zeros), row stride Wp; tp/cp may be NULL.
   order: the no offset ids (dy+R)*S + (dx+R) to visit (centre first, so that the running k-th
   distance is tight early and few candidates need an insertion). Keys are compared as
   (distance, id), so ties go to the smaller id whatever the visiting order.
   both (may be NULL): both[io] = 1 for an offset o with dy > 0 (or dy = 0, dx > 0) whose mirror -o is
   not in order: the block distance is symmetric, d(p, p+o) = d(p+o, p), so each one computed for p
   is also offered to pixel p+o under the id of -o, and the mirrored offsets are never computed. */
int bm_rows_SFX(const REAL* xp, const REAL* tp, const REAL* cp, int nc, int64_t Hp, int64_t Wp,
                int H, int W, int r, int R, const int32_t* order, const int8_t* both, int no, int k, double rho,
                int h0, int h1, REAL* topd, int32_t* topi)
{
    const int bs = 2 * r + 1, S = 2 * R + 1, U = W + 2 * r, rows = h1 - h0;
    const REAL nb = (REAL)(bs * bs);
    const REAL cw = nc > 0 ? (REAL)(rho / nc) : 0;
    const REAL crho = nc > 0 ? (REAL)(rho / (nc * (double)bs * bs)) : 0;
    const int nbuf = tp ? 3 : 1;
    REAL* ring = (REAL*)malloc(sizeof(REAL) * (size_t)nbuf * bs * U);
    REAL* col = (REAL*)malloc(sizeof(REAL) * (size_t)(nbuf + 1) * U);
    if (!ring || !col) { free(ring); free(col); return -1; }
    REAL* dd = col + (size_t)nbuf * U;
    for (int64_t p = 0; p < (int64_t)rows * W * k; ++p) { topd[p] = (REAL)INFINITY; topi[p] = 0x7fffffff; }
    for (int io = 0; io < no; ++io) {
        const int32_t oid = order[io];
        const int dy = oid / S - R, dx = oid % S - R;
        const int32_t mid = (R - dy) * S + (R - dx);
        const int f0 = h0 > -dy ? h0 : -dy, f1 = h1 < H - dy ? h1 : H - dy;  /* rows of p in the chunk */
        int i0 = f0, i1 = f1;
        int m0 = 0, m1 = 0;  /* rows i whose mirrored pixel (i+dy, j+dx) is in the chunk (dy >= 0) */
        if (both && both[io]) {
            m0 = h0 - dy > 0 ? h0 - dy : 0;
            m1 = h1 - dy < H - dy ? h1 - dy : H - dy;
            if (m1 > m0) {
                if (f1 <= f0) { i0 = m0; i1 = m1; }
                else { i0 = i0 < m0 ? i0 : m0; i1 = i1 > m1 ? i1 : m1; }
            }
        }
        if (i1 <= i0) continue;
        {
            const int j0 = dx < 0 ? -dx : 0, j1 = dx > 0 ? W - dx : W;
            for (int t = i0; t < i1 + 2 * r; ++t) {
                const int slot = t % bs;
                const REAL* xa = xp + (int64_t)(R + t) * Wp + R;
                const REAL* xb = xp + (int64_t)(R + t + dy) * Wp + R + dx;
                REAL* e = ring + (size_t)slot * U;
                if (!tp) {
                    for (int u = 0; u < U; ++u) { REAL df = xa[u] - xb[u]; e[u] = df * df; }
                    for (int c = 0; c < nc; ++c) {
                        const REAL* ca = cp + ((int64_t)c * Hp + R + t) * Wp + R;
                        const REAL* cb = cp + ((int64_t)c * Hp + R + t + dy) * Wp + R + dx;
                        for (int u = 0; u < U; ++u) { REAL dc = ca[u] - cb[u]; e[u] += cw * (dc * dc); }
                    }
                } else {
                    REAL* et = ring + (size_t)(bs + slot) * U;
                    REAL* ec = ring + (size_t)(2 * bs + slot) * U;
                    const REAL* ta = tp + (int64_t)(R + t) * Wp + R;
                    const REAL* tb = tp + (int64_t)(R + t + dy) * Wp + R + dx;
                    for (int u = 0; u < U; ++u) {
                        REAL tt = ta[u] * tb[u], df = xa[u] - xb[u];
                        e[u] = tt * (df * df); et[u] = tt; ec[u] = 0;
                    }
                    for (int c = 0; c < nc; ++c) {
                        const REAL* ca = cp + ((int64_t)c * Hp + R + t) * Wp + R;
                        const REAL* cb = cp + ((int64_t)c * Hp + R + t + dy) * Wp + R + dx;
                        for (int u = 0; u < U; ++u) { REAL dc = ca[u] - cb[u]; ec[u] += dc * dc; }
                    }
                }
                if (t < i0 + 2 * r) continue;
                const int i = t - 2 * r;
                for (int b = 0; b < nbuf; ++b) {
                    REAL* cs = col + (size_t)b * U;
                    const REAL* rb = ring + (size_t)b * bs * U;
                    for (int u = 0; u < U; ++u) cs[u] = rb[u];
                    for (int s2 = 1; s2 < bs; ++s2)
                        for (int u = 0; u < U; ++u) cs[u] += rb[(size_t)s2 * U + u];
                }
                for (int j = j0; j < j1; ++j) dd[j] = col[j];
                for (int q = 1; q < bs; ++q)
                    for (int j = j0; j < j1; ++j) dd[j] += col[j + q];
                if (!tp) {
                    const REAL inb = 1 / nb;
                    for (int j = j0; j < j1; ++j) dd[j] *= inb;
                } else {
                    const REAL* c1 = col + U;
                    const REAL* c2 = col + 2 * U;
                    for (int j = j0; j < j1; ++j) {
                        REAL s1 = c1[j], s2 = c2[j];
                        for (int q = 1; q < bs; ++q) { s1 += c1[j + q]; s2 += c2[j + q]; }
                        dd[j] = dd[j] / (s1 > 1 ? s1 : 1) + crho * s2;
                    }
                }
                for (int j = j0; j < j1; ++j) dd[j] = dd[j] > 0 ? dd[j] : 0;
                if (i >= f0 && i < f1) {  /* pixel (i, j) gets candidate (i+dy, j+dx) */
                    const int64_t at = (int64_t)(i - h0) * W * k;
                    offer_row_SFX(dd, j0, j1, oid, topd + at, topi + at, k);
                }
                if (i >= m0 && i < m1) {  /* pixel (i+dy, j+dx) gets candidate (i, j) */
                    const int64_t at = ((int64_t)(i + dy - h0) * W + dx) * k;
                    offer_row_SFX(dd, j0, j1, mid, topd + at, topi + at, k);
                }
            }
        }
    }
    free(ring); free(col);
    return 0;
}
"""

_C_TEMPLATE += r"""
/* One round of the singular-pixel test of singular.py for pixels [i0, i1) of one sample (HW pixels,
   k matches). y0: observation (0 where missing), obs: 1/0, x: current estimate, idx: (k, HW) flat
   centres, w0: (k, HW) weights; qo: Q of the previous round (read), qn, p (out, for [i0, i1)).
   Returns the number of pixels whose Q changed. Same arithmetic as the torch path, pixel by pixel;
   rounds are separate calls so that threads can split the pixels of a round. */
int64_t singular_round_SFX(const REAL* y0, const uint8_t* obs, const REAL* x, const int64_t* idx, const REAL* w0,
                           int64_t HW, int k, REAL floor_, REAL tau, const REAL* qo, REAL* qn, REAL* p,
                           int64_t i0, int64_t i1)
{
    if (k > KMAX) return -1;
    int64_t changed = 0;
    for (int64_t i = i0; i < i1; ++i) {
        if (!obs[i]) { p[i] = 0; qn[i] = 0; changed += qo[i] != 0; continue; }
        REAL s = 0, wm[KMAX], xm[KMAX];
        for (int m = 0; m < k; ++m) {
            const int64_t j = idx[(int64_t)m * HW + i];
            wm[m] = w0[(int64_t)m * HW + i]; xm[m] = x[j];
            s += wm[m] * qo[j];
        }
        if (s > 0) {  /* like the torch path's clamp_min(tiny): a subnormal s would give 1/s = inf, 0*inf = NaN */
            const REAL inv = 1 / (s > REAL_MIN ? s : REAL_MIN);
            for (int m = 0; m < k; ++m) wm[m] *= qo[idx[(int64_t)m * HW + i]] * inv;
        }
        REAL mu = 0;
        for (int m = 0; m < k; ++m) mu += wm[m] * xm[m];
        REAL var = 0;
        for (int m = 0; m < k; ++m) { const REAL d = xm[m] - mu; var += wm[m] * d * d; }
        REAL sg = var > 0 ? (REAL)sqrt((double)var) : 0;
        if (sg < floor_) sg = floor_;
        const REAL r = y0[i] - mu;
        const REAL pi = (REAL)exp(-(double)(r * r) / (double)(2 * sg * sg));
        p[i] = pi;
        qn[i] = pi >= tau ? 1 : 0;
        changed += qn[i] != qo[i];
    }
    return changed;
}
"""

_C_HEADER = ("#include <stdint.h>\n#include <stdlib.h>\n#include <math.h>\n#include <float.h>\n#define KMAX 256\n"
             "#define float_MIN FLT_MIN\n#define double_MIN DBL_MIN\n")
_CLIB = None
_CLIB_TRIED = False


def _c_source() -> str:
    body = [_C_TEMPLATE.replace("REAL", t).replace("SFX", s) for t, s in (("float", "f32"), ("double", "f64"))]
    return _C_HEADER + "\n".join(body)


def _load_clib():
    """Compile (once, cached under ``~/.cache/torch_depth_sr``) and load the C kernel; None if impossible.

    Set ``TORCH_DEPTH_SR_NO_CEXT=1`` to disable it (then the numpy/OpenCV path runs). The cached
    library is verified against its sha256 sidecar before it is loaded (a truncated file would kill
    the process with SIGBUS inside ``dlopen``); a missing or mismatching sidecar means a rebuild.
    """
    global _CLIB, _CLIB_TRIED
    if _CLIB_TRIED:
        return _CLIB
    _CLIB_TRIED = True
    if os.environ.get("TORCH_DEPTH_SR_NO_CEXT", "") not in ("", "0"):
        return None
    import ctypes
    import hashlib
    import platform
    import shutil

    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if cc is None:
        return None
    flags = ["-O3", "-march=native", "-fPIC", "-shared", "-std=c99"]
    src = _c_source()
    key = hashlib.sha1((src + " ".join(flags) + platform.machine() + platform.node()).encode()).hexdigest()[:16]
    cache = os.environ.get("TORCH_DEPTH_SR_CACHE") or os.path.join(os.path.expanduser("~"), ".cache",
                                                                    "torch_depth_sr")
    path = os.path.join(cache, f"bm_{key}.so")
    try:
        if not _cache_is_intact(path):
            _build_clib(cc, flags, src, path)
        if not _cache_is_intact(path):  # e.g. another process replaced it mid-way, or the disk is full
            raise OSError(f"the rebuilt {path} does not match its checksum")
        lib = ctypes.CDLL(path)
    except Exception as exc:  # no compiler, read-only home, sandbox: fall back to numpy/OpenCV
        if os.path.exists(path):  # a cache exists but cannot be used: say so once (this runs once per process)
            import warnings

            warnings.warn(f"torch_depth_sr: cannot use the cached C kernel {path} ({exc}); block matching falls "
                          "back to numpy. Delete the file to rebuild it.", RuntimeWarning, stacklevel=3)
        return None
    i64, i32, dbl, vp = ctypes.c_int64, ctypes.c_int, ctypes.c_double, ctypes.c_void_p
    for name in ("bm_rows_f32", "bm_rows_f64"):
        fn = getattr(lib, name)
        fn.restype = i32
        fn.argtypes = [vp, vp, vp, i32, i64, i64, i32, i32, i32, i32, vp, vp, i32, i32, dbl, i32, i32, vp, vp]
    for name in ("singular_round_f32", "singular_round_f64"):
        fn = getattr(lib, name)
        fn.restype = i64
        real = dbl if name.endswith("64") else ctypes.c_float
        fn.argtypes = [vp, vp, vp, vp, vp, i64, i32, real, real, vp, vp, vp, i64, i64]
    _CLIB = lib
    return lib


def _sha256_file(path: str) -> str:
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _cache_is_intact(path: str) -> bool:
    """Whether ``path`` exists and matches the sha256 in ``path + '.sha256'`` (written after each build)."""
    try:
        with open(path + ".sha256") as f:
            expected = f.read().strip()
        return bool(expected) and _sha256_file(path) == expected
    except OSError:
        return False


def _replace_atomically(path: str, data_from: str | None = None, text: str | None = None) -> None:
    """Put a file at ``path`` by writing a temporary sibling and ``os.replace``: readers see old or new, never half."""
    tmp = f"{path}.{os.getpid()}.tmp"
    try:
        if data_from is not None:
            import shutil

            shutil.copyfile(data_from, tmp)
            os.chmod(tmp, 0o755)
        else:
            with open(tmp, "w") as f:
                f.write(text or "")
        with open(tmp, "rb") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _build_clib(cc: str, flags: list, src: str, path: str) -> None:
    """Compile the kernel in a temporary folder, then install it and its sha256 sidecar under ``path``."""
    import subprocess
    import tempfile

    os.makedirs(os.path.dirname(path), exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        c_file = os.path.join(tmp, "bm.c")
        with open(c_file, "w") as f:
            f.write(src)
        out = os.path.join(tmp, "bm.so")
        subprocess.run([cc, *flags, c_file, "-o", out, "-lm"], check=True, capture_output=True, timeout=120)
        digest = _sha256_file(out)
        # library first, then its checksum: a reader between the two sees a mismatch and rebuilds (never loads
        # an unverified file)
        _replace_atomically(path, data_from=out)
        _replace_atomically(path + ".sha256", text=digest + "\n")


def _offset_order(search_window: int, stride: int, include_self: bool) -> np.ndarray:
    """Offset ids of the lattice, nearest to the centre first (ties by id)."""
    big_r = search_window // 2
    offs = [((dy * dy + dx * dx), (dy + big_r) * search_window + dx + big_r)
            for dy in _lattice(big_r, stride) for dx in _lattice(big_r, stride)
            if include_self or dy != 0 or dx != 0]
    return np.array([o for _, o in sorted(offs)], dtype=np.int32)


def _symmetric_order(order: np.ndarray, search_window: int) -> tuple[np.ndarray, np.ndarray]:
    """Keep one offset of each mirrored pair (the one with dy > 0, or dy = 0 and dx > 0), flagged ``both``.

    The block distance is symmetric, so the kernel offers each distance computed for ``(p, p+o)`` to
    pixel ``p+o`` as its candidate ``-o`` too: half the offsets, the same matches.
    """
    big_r = search_window // 2
    ids = set(order.tolist())
    keep, both = [], []
    for o in order.tolist():
        dy, dx = o // search_window - big_r, o % search_window - big_r
        mirror = (big_r - dy) * search_window + (big_r - dx)
        if mirror == o or mirror not in ids:
            keep.append(o)
            both.append(0)
        elif dy > 0 or (dy == 0 and dx > 0):
            keep.append(o)
            both.append(1)
    return np.array(keep, dtype=np.int32), np.array(both, dtype=np.int8)


def _block_match_c(lib, depth, rgb, trust, block_size, search_window, k, rho, include_self, chunk_rows, stride):
    bsz, _, h, w = depth.shape
    r, big_r = block_size // 2, search_window // 2
    f64 = depth.dtype == torch.float64
    npdt = np.float64 if f64 else np.float32
    fn = lib.bm_rows_f64 if f64 else lib.bm_rows_f32
    if chunk_rows is None:
        # taller chunks share more of each mirrored offset pair's rows (measured at 640×480, 2 threads:
        # 8 rows 0.67 s, 16 rows 0.65 s, 32 rows 0.50 s per run)
        chunk_rows = 32
    samples, jobs = [], []
    for b in range(bsz):
        xp = np.ascontiguousarray(_pad_plane(depth[b, 0].cpu().numpy().astype(npdt, copy=False), r, big_r))
        tp = None if trust is None else np.ascontiguousarray(
            _pad_plane(trust[b, 0].cpu().numpy().astype(npdt, copy=False), r, big_r))
        cp = None if rgb is None else np.ascontiguousarray(np.stack(
            [_pad_plane(rgb[b, c].cpu().numpy().astype(npdt, copy=False), r, big_r) for c in range(rgb.shape[1])]))
        samples.append((xp, tp, cp, float(rho[b])))
        for h0 in range(0, h, chunk_rows):
            jobs.append((b, h0, min(h, h0 + chunk_rows)))
    topd = np.empty((bsz, h * w, k), dtype=npdt)
    order, both = _symmetric_order(_offset_order(search_window, stride, include_self), search_window)
    topi = np.empty((bsz, h * w, k), dtype=np.int32)

    def run(job):
        b, h0, h1 = job
        xp, tp, cp, rb = samples[b]
        td, ti = topd[b, h0 * w:h1 * w], topi[b, h0 * w:h1 * w]
        rc = fn(xp.ctypes.data, None if tp is None else tp.ctypes.data, None if cp is None else cp.ctypes.data,
                0 if cp is None else cp.shape[0], xp.shape[0], xp.shape[1], h, w, r, big_r, order.ctypes.data,
                both.ctypes.data, len(order), k, rb, h0, h1, td.ctypes.data, ti.ctypes.data)
        if rc != 0:
            raise MemoryError("block matching kernel could not allocate its row buffers")

    workers = max(1, min(len(jobs), torch.get_num_threads(), os.cpu_count() or 1))
    if workers > 1:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            list(pool.map(run, jobs))
    else:
        for j in jobs:
            run(j)
    dist = torch.from_numpy(topd).permute(0, 2, 1).reshape(bsz, k, h, w).to(depth.dtype)  # (B, k, H, W)
    del topd
    index = _index_from_offsets(torch.from_numpy(topi).view(bsz, h, w, k).permute(0, 3, 1, 2), search_window, h, w)
    return dist.contiguous(), index.contiguous()  # (B, k, H, W) contiguous: every layer's gathers read it


# ----------------------------------------------------------------------------------------------
# fast path, any device: torch
# ----------------------------------------------------------------------------------------------


# Ways of selecting the k smallest of the torch path's (B, pixels, candidates) keys. All return the
# same keys (they are unique) and differ in speed only; "split" is used: PyTorch's torch.topk takes a
# slow multi-block radix path for >= 400 candidates over > 4000 slices (H200, 640×480: topk 13.0 ms,
# split 6.5 ms, sort 14.9 ms; docs/measurements/h200-2026-11-28/gpu_report.json).
_SELECT_CHOICES = ("topk", "split", "sort")


def _smallest_keys(keys: torch.Tensor, k: int, how: str = "split") -> torch.Tensor:
    """``(B, P, N)`` int64 keys -> ``(B, P, k)``: the ``k`` smallest of every row, ascending."""
    n = keys.shape[2]
    if how == "topk" or (how == "split" and (n < 400 or n <= 2 * k)):
        return torch.topk(keys, k, dim=2, largest=False, sorted=True).values
    if how == "sort":
        return torch.sort(keys, dim=2).values[..., :k]
    if how == "split":  # halves under 400 candidates each, then the 2k survivors
        parts = [torch.topk(p, k, dim=2, largest=False, sorted=False).values for p in keys.split((n + 1) // 2, dim=2)]
        return torch.topk(torch.cat(parts, dim=2), k, dim=2, largest=False, sorted=True).values
    raise DepthSRError(f"selection must be one of {_SELECT_CHOICES}; got {how!r}.")


def _block_match_torch(depth, rgb, trust, block_size, search_window, k, rho, include_self, chunk_rows, stride):
    """All offsets of a band of rows at once; the mirrored half read back from the other half.

    The distance is symmetric, ``d(i, i + o) = d(i + o, i)``, and so are the box sums that give it
    (same pixels, same order). Distances are computed for the offsets with ``dy >= 0`` only, over the
    band widened by ``R`` rows above and ``R`` columns on each side; offset ``−o`` at pixel ``i`` is
    then the ``o`` map at ``i − o``, an ``as_strided`` view of the same tensor. Bitwise equal to
    computing every offset directly.
    """
    bsz, _, h, w = depth.shape
    r, big_r, s = block_size // 2, search_window // 2, search_window
    nb = float(block_size * block_size)
    dev = depth.device
    cdt = torch.float64 if depth.dtype == torch.float64 else torch.float32
    low_mask = (1 << max(1, (s * s - 1).bit_length())) - 1
    lat = _lattice(big_r, stride)  # symmetric about 0
    g = len(lat)
    half = lat[lat.index(0):]  # dy >= 0
    n_h = len(half)
    n_off = g * g  # candidates per pixel: rows 0..n_h-1 of the key grid direct, n_h.. mirrored
    offs = torch.tensor(lat, device=dev)
    dy_grid = torch.tensor(half + [-d for d in half[1:]], device=dev)  # (2n_h−1,)
    dx_grid = torch.cat([offs.expand(n_h, g), -offs.expand(n_h - 1, g)])  # (2n_h−1, G)
    oid_grid = (dy_grid[:, None] + big_r) * s + dx_grid + big_r  # (2n_h−1, G)
    centre = lat.index(0)

    def pad(img):  # (B,C,H,W) -> replicate by r, then zeros: R rows, 2R columns
        img = F.pad(img.detach().to(cdt), (r,) * 4, mode="replicate")
        return F.pad(img, (2 * big_r, 2 * big_r, big_r, big_r)).contiguous()

    xp = pad(depth)[:, 0]  # (B, Hp, Wp); image pixel (y, x) at (y + r + R, x + r + 2R)
    tp = None if trust is None else pad(trust)[:, 0]
    cp = None if rgb is None else pad(rgb)  # (B, C, Hp, Wp)
    ncol = 0 if rgb is None else rgb.shape[1]
    rho = rho.to(device=dev, dtype=cdt).view(-1, 1, 1, 1, 1)
    if chunk_rows is None:  # elements of the (B, rows, W, G·G) keys: 2²² on CPU, 2²⁶ on a GPU
        budget = 2 ** 26 if dev.type == "cuda" else 2 ** 22
        chunk_rows = max(1, min(h, budget // max(1, bsz * n_off * w)))
    xs = torch.arange(w, device=dev)[:, None, None] + dx_grid  # (W, 2n_h−1, G) candidate columns
    col_ok = (xs >= 0) & (xs < w)
    top_all = torch.empty(bsz, k, h, w, dtype=torch.int64, device=dev)
    ext_w = w + 2 * big_r  # centres x in [−R, W+R)

    def candidates(p, h0, ext_rows):  # (..., Hp, Wp) -> (..., n_h, G, ext_rows+2r, ext_w+2r)
        st = p.stride()  # block of centre (h0 − R + u, −R + v) shifted by (half[a], lat[c])
        start = p[..., h0:, big_r + lat[0]:]
        return start.as_strided((*p.shape[:-2], n_h, g, ext_rows + 2 * r, ext_w + 2 * r),
                                (*st[:-2], st[-2] * stride, st[-1] * stride, st[-2], st[-1]), start.storage_offset())

    def box(a):  # (B, n_h, G, hh, ww) -> (B, n_h, G, hh−2r, ww−2r) unnormalised b×b sums
        bb, _, _, hh, ww = a.shape
        y = F.avg_pool2d(a.reshape(bb * n_h * g, 1, hh, ww), block_size, stride=1)
        return y.view(bb, n_h, g, hh - 2 * r, ww - 2 * r) * nb

    for h0 in range(0, h, chunk_rows):
        h1 = min(h, h0 + chunk_rows)
        rows = h1 - h0
        ext_rows = rows + big_r  # centres y in [h0 − R, h1)
        here = (slice(h0, h0 + ext_rows + 2 * r), slice(big_r, big_r + ext_w + 2 * r))
        e = (xp[:, None, None, here[0], here[1]] - candidates(xp, h0, ext_rows)).square_()
        if tp is not None:
            tt = tp[:, None, None, here[0], here[1]] * candidates(tp, h0, ext_rows)
            e.mul_(tt)
        csum = None
        if cp is not None:
            cand_c = candidates(cp, h0, ext_rows)  # (B, C, n_h, G, ext_rows+2r, ext_w+2r)
            for c in range(ncol):
                sq = (cp[:, c, None, None, here[0], here[1]] - cand_c[:, c]).square_()
                csum = sq if csum is None else csum.add_(sq)
        if tp is None:
            if csum is not None:
                e.add_(csum.mul_(rho / ncol))
            d = box(e).div_(nb)
        else:
            d = box(e).div_(box(tt).clamp_min_(1.0))
            if csum is not None:
                d.add_(box(csum).mul_(rho / (ncol * nb)))
        del e, csum
        d = d.clamp_min_(0.0).add_(0.0).contiguous()  # (B, n_h, G, ext_rows, ext_w); + 0.0 turns -0.0 into +0.0
        sb, sa, sc, su, sv = d.stride()
        direct = d[:, :, :, big_r:big_r + rows, big_r:big_r + w]  # offset (half[a], lat[c]) at (i, j)
        # offset (−half[a], −lat[c]) at (i, j) is the (half[a], lat[c]) map at (i − half[a], j − lat[c])
        mirrored = d.as_strided((bsz, n_h - 1, g, rows, w), (sb, sa - stride * su, sc - stride * sv, su, sv),
                                d.storage_offset() + sa + (big_r - half[1]) * su + (big_r - lat[0]) * sv
                                ) if n_h > 1 else None
        # float64 bit patterns, candidates last (transposing copies), offset id in the low bits
        keys = torch.empty(bsz, rows, w, 2 * n_h - 1, g, dtype=torch.float64, device=dev)
        keys[..., :n_h, :].copy_(direct.permute(0, 3, 4, 1, 2))
        if mirrored is not None:
            keys[..., n_h:, :].copy_(mirrored.permute(0, 3, 4, 1, 2))
        del d, direct, mirrored
        keys = keys.view(torch.int64)
        if cdt == torch.float64:
            keys &= ~low_mask
        keys |= oid_grid
        ys = torch.arange(h0, h1, device=dev)[:, None] + dy_grid  # (rows, 2n_h−1)
        row_ok = (ys >= 0) & (ys < h)
        keys.masked_fill_(~(row_ok[:, None, :, None] & col_ok[None]), _INT64_MAX)
        keys[..., 0, centre] = oid_grid[0, centre] if include_self else _INT64_MAX
        top = _smallest_keys(keys.view(bsz, rows * w, n_off), k)  # (B, rows·W, k)
        top_all[:, :, h0:h1] = top.transpose(1, 2).reshape(bsz, k, rows, w)
    oid_top = top_all & low_mask
    dist = (top_all & ~low_mask).view(torch.float64).to(depth.dtype)
    return dist.contiguous(), _index_from_offsets(oid_top, search_window, h, w)


def block_match(
    depth: torch.Tensor,
    rgb: Optional[torch.Tensor] = None,
    trust: Optional[torch.Tensor] = None,
    block_size: int = 5,
    search_window: int = 21,
    k: int = 10,
    color_weight: Scalar = 1.0,
    temperature: Scalar = 1.0,
    include_self: bool = False,
    chunk_rows: Optional[int] = None,
    *,
    search_stride: int = 1,
    backend: str = "auto",
) -> BlockMatches:
    """The ``k`` most similar blocks to the block around every pixel, by shift-and-box-filter.

    .. math::

        d(i, j) = \\frac{\\sum_p t_i(p) t_j(p) (x_i(p) - x_j(p))^2}{\\max(1, \\sum_p t_i(p) t_j(p))}
                  + \\rho\\, \\operatorname{mean}_{p,c} (c_i(p) - c_j(p))^2,
        \\qquad \\omega_{ij} = \\operatorname{softmax}_j(-d(i, j) / h)

    Candidates ``j`` lie in the ``S×S`` search window around ``i`` and inside the image; block pixels
    outside the image are replicate-padded. Computed without gradient; equal (to float round-off) to
    :func:`block_match_reference`. Distances are computed in float32 for float32 inputs (OpenCV box
    sums accumulate in float64) and in float64 for float64 inputs, where the 9 lowest mantissa bits
    (for ``S = 21``) carry the offset id (relative perturbation ≤ 2⁻⁴³).

    Args:
        depth: ``(B, 1, H, W)`` float depth (the current estimate; it should have no holes).
        rgb: ``(B, C, H, W)`` colour guide (usually ``C = 3`` in ``[0, 1]``) or ``None`` (depth only).
        trust: ``(B, 1, H, W)`` {0, 1} mask of trusted depth pixels, or ``None`` (all trusted).
        block_size: odd block side ``b`` (5).
        search_window: odd search window side ``S`` (21).
        k: number of blocks kept (10); must not exceed the candidates at an image corner.
        color_weight: ``ρ``, float or ``(B,)`` tensor (≥ 0).
        temperature: ``h`` of the weights, float or ``(B,)`` tensor (> 0). A tensor requiring grad gets
            a gradient through ``weight``.
        include_self: keep the centre block ``j = i`` (distance 0) as a candidate.
        chunk_rows: image rows per chunk (memory/speed trade-off); ``None`` picks a cache-friendly size.
        search_stride: evaluate only offsets whose ``dy`` and ``dx`` are multiples of it (1 = the exact
            full search, the default; 2 ≈ 3.6× fewer offsets for ``S = 21``).
        backend: ``"auto"`` (OpenCV/numpy on CPU, torch elsewhere), ``"numpy"`` or ``"torch"``.

    Returns:
        :class:`BlockMatches` ``(dist, index, weight)``, each ``(B, k, H, W)``, sorted by ``dist``.

    Raises:
        ShapeError: wrong ndim/channels, mismatched sizes, image smaller than a block.
        DepthSRError: even/invalid sizes, ``k`` larger than the candidates, negative weights.

    Examples:
        >>> depth = torch.rand(2, 1, 32, 40)
        >>> rgb = torch.rand(2, 3, 32, 40)
        >>> m = block_match(depth, rgb, None, block_size=5, search_window=11, k=6)
        >>> m.dist.shape, m.index.dtype
        (torch.Size([2, 6, 32, 40]), torch.int64)
        >>> bool(torch.allclose(m.weight.sum(1), torch.ones(2, 32, 40)))
        True
        >>> neighbours = gather_neighbors(depth, m.index)  # (B, 1, k, H, W)
    """
    rho, temp = _prepare(depth, rgb, trust, block_size, search_window, k, color_weight, temperature,
                         include_self, search_stride)
    if backend not in ("auto", "c", "numpy", "torch"):
        raise DepthSRError(f"backend must be 'auto', 'c', 'numpy' or 'torch'; got {backend!r}.")
    if chunk_rows is not None and (isinstance(chunk_rows, bool) or not isinstance(chunk_rows, int)
                                   or chunk_rows < 1):
        raise DepthSRError(f"chunk_rows must be None or an int >= 1; got {chunk_rows!r}.")
    lib = None
    if backend in ("auto", "c") and depth.device.type == "cpu":
        lib = _load_clib()
        if lib is None and backend == "c":
            raise DepthSRError("backend='c' needs a C compiler (cc/gcc) to build the block-matching kernel; "
                               "none worked. Use backend='auto' or 'numpy'.")
    if backend in ("auto", "c"):
        backend = "c" if lib is not None else ("numpy" if depth.device.type == "cpu" else "torch")
    with torch.no_grad():
        if trust is not None:
            trust = trust.to(depth.dtype)
        if rgb is not None:
            rgb = rgb.to(depth.dtype)
        args = (depth, rgb, trust, block_size, search_window, k, rho.detach(), include_self, chunk_rows,
                search_stride)
        if backend == "c":
            dist, index = _block_match_c(lib, *args)
        elif backend == "numpy":
            dist, index = _block_match_numpy(*args)
        else:
            dist, index = _block_match_torch(*args)
    return _finish(dist.to(depth.device), index.to(depth.device), temp)


def gather_neighbors(values: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """Values at the matched block centres: ``out[b, c, m, i, j] = values[b, c].flatten()[index[b, m, i, j]]``.

    Args:
        values: ``(B, C, H, W)`` tensor (differentiable).
        index: ``(B, k, H, W)`` int64 flat indices from :class:`BlockMatches`.

    Returns:
        ``(B, C, k, H, W)`` tensor; gradients flow back to ``values``.

    Examples:
        >>> v = torch.arange(6.).view(1, 1, 2, 3)
        >>> idx = torch.tensor([[[[5, 4, 3], [2, 1, 0]]]])
        >>> gather_neighbors(v, idx)[0, 0, 0]
        tensor([[5., 4., 3.],
                [2., 1., 0.]])
    """
    check_4d(values, "values")
    check_4d(index, "index")
    if index.dtype != torch.int64:
        raise DepthSRError(f"index must be int64 (from BlockMatches.index); got {index.dtype}.")
    if index.shape[0] != values.shape[0] or index.shape[-2:] != values.shape[-2:]:
        raise ShapeError(f"values {tuple(values.shape)} and index {tuple(index.shape)} must share batch size "
                         f"and height/width.")
    b, c, h, w = values.shape
    k = index.shape[1]
    flat = values.reshape(b, c, h * w)  # (B, C, HW)
    idx = index.reshape(b, 1, k * h * w).expand(b, c, k * h * w)  # (B, C, k·HW)
    return torch.gather(flat, 2, idx).view(b, c, k, h, w)  # (B, C, k, H, W)
