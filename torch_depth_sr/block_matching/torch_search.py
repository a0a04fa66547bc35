"""Exact block matching on any device with torch: all offsets of a band of rows at once.

Few, large launches suit a GPU. The offset id is packed into the low bits of the distance's float64 bit
pattern (a float32 distance has 29 unused low bits there), so one integer selection picks distance and
index together, without an argsort. Rows are processed in chunks, so memory stays bounded (about 2 GB
on a GPU at any image size).
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import torch
import torch.nn.functional as F

from ..errors import DepthSRError
from ._common import index_from_offsets, lattice

__all__ = ["block_match_torch", "decode_keys", "encode_keys", "smallest_keys", "top_keys"]

_INT64_MAX = np.iinfo(np.int64).max



# Ways of selecting the k smallest of the torch path's (B, pixels, candidates) keys. All return the
# same keys (they are unique) and differ in speed only; "split" is used: PyTorch's torch.topk takes a
# slow multi-block radix path for >= 400 candidates over > 4000 slices (H200, 640×480: topk 13.0 ms,
# split 6.5 ms, sort 14.9 ms; docs/measurements/h200-2026-11-28/gpu_report.json).
_SELECT_CHOICES = ("topk", "split", "sort")


def smallest_keys(keys: torch.Tensor, k: int, how: str = "split") -> torch.Tensor:
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


def block_match_torch(depth: torch.Tensor, rgb: Optional[torch.Tensor], trust: Optional[torch.Tensor],
                      block_size: int, search_window: int, k: int, rho: torch.Tensor, include_self: bool,
                      chunk_rows: Optional[int], stride: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``(dist, index)`` (B, k, H, W): the ``k`` best blocks among the offsets of the ``stride`` lattice (see
    :func:`top_keys`)."""
    top = top_keys(depth, rgb, trust, block_size, search_window, k, rho, include_self, chunk_rows, stride)
    return decode_keys(top, search_window, depth.dtype)


def offset_bits(search_window: int) -> int:
    """The mask of the low bits of a key that hold the offset id ``(dy+R)·S + (dx+R)``."""
    s = search_window
    return (1 << max(1, (s * s - 1).bit_length())) - 1


def encode_keys(dist: torch.Tensor, oid: torch.Tensor, search_window: int) -> torch.Tensor:
    """int64 keys of non-negative distances and their offset ids: the float64 bit pattern of the distance with the
    id in its low bits (a float32 distance leaves them zero; a float64 one loses them), so that keys order as
    (distance, id) pairs do."""
    low_mask = offset_bits(search_window)
    keys = dist.to(torch.float64).view(torch.int64)
    if dist.dtype == torch.float64:
        keys = keys & ~low_mask
    return keys | oid


def decode_keys(keys: torch.Tensor, search_window: int, dtype: torch.dtype) -> tuple[torch.Tensor, torch.Tensor]:
    """``(dist, index)`` from keys (B, k, H, W): the distances in ``dtype`` and the flat indices of the blocks."""
    low_mask = offset_bits(search_window)
    h, w = keys.shape[-2:]
    dist = (keys & ~low_mask).view(torch.float64).to(dtype)
    return dist.contiguous(), index_from_offsets(keys & low_mask, search_window, h, w)


def top_keys(depth: torch.Tensor, rgb: Optional[torch.Tensor], trust: Optional[torch.Tensor],
             block_size: int, search_window: int, k: int, rho: torch.Tensor, include_self: bool,
             chunk_rows: Optional[int], stride: int) -> torch.Tensor:
    """The ``k`` smallest keys (:func:`encode_keys`) per pixel, (B, k, H, W) int64, ascending: all offsets of a band
    of rows at once; the mirrored half read back from the other half. Where fewer than ``k`` offsets of the
    lattice lie in the image, the last keys are ``_INT64_MAX`` (no candidate).

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
    low_mask = offset_bits(search_window)
    lat = lattice(big_r, stride)  # symmetric about 0
    g = len(lat)
    half = lat[lat.index(0):]  # dy >= 0
    n_h = len(half)
    n_off = g * g  # candidates per pixel: rows 0..n_h-1 of the key grid direct, n_h.. mirrored
    # the offsets made on the device (aranges, not a copy from the host, which a CUDA graph cannot capture)
    offs = torch.arange(lat[0], lat[-1] + 1, lat[1] - lat[0] if g > 1 else 1, device=dev)
    dy_half = offs[lat.index(0):]
    dy_grid = torch.cat([dy_half, -dy_half[1:]])  # (2n_h−1,): 0, s, 2s, ..., −s, −2s, ...
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
        if include_self:
            keys[..., 0, centre] = oid_grid[0, centre]
        else:  # a fill, not an item set from a host number (that copies it to the device; a graph cannot capture it)
            keys[..., 0, centre].fill_(_INT64_MAX)
        top = smallest_keys(keys.view(bsz, rows * w, n_off), min(k, n_off))  # (B, rows·W, k) ascending
        if n_off < k:  # a lattice with fewer offsets than k (a 7×7 window at stride 2 has 9): the rest no candidate
            top = torch.cat([top, top.new_full((bsz, rows * w, k - n_off), _INT64_MAX)], dim=2)
        top_all[:, :, h0:h1] = top.transpose(1, 2).reshape(bsz, k, rows, w)
    return top_all
