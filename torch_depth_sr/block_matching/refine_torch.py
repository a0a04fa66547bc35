"""The re-matching of :func:`~torch_depth_sr.block_matching.refine_matches` in torch: the device path's twin of
the CPU kernel (:mod:`.refine_cpu`), with the same candidates.

A pixel's candidates are its previous matches and the window's offsets on the lattice. The lattice is searched by the
exact torch search with that stride (:func:`.torch_search.top_keys`); a previous match off the lattice is re-scored
directly over its block, in the order in which the CPU kernel sums (the same float32 operations, so the same
distance); one on the lattice is already among the searched. The result is the ``k`` smallest (distance, offset id)
pairs of both, as in the kernel's sorted lists. The lattice's distances are the torch search's box sums, which can
differ from the CPU kernel's in the last bit: a near-tie may then rank the other way.

Whole-image tensors of (B, previous matches, H, W), one gather per block pixel and plane (the pixel's own block
is a shifted view): few, large launches.
"""
from __future__ import annotations

from typing import Optional

import torch
import torch.nn.functional as F

from .torch_search import _INT64_MAX, decode_keys, encode_keys, smallest_keys, top_keys

__all__ = ["refine_torch"]


def _rescored(depth: torch.Tensor, rgb: Optional[torch.Tensor], trust: Optional[torch.Tensor], dy: torch.Tensor,
              dx: torch.Tensor, block_size: int, rho: torch.Tensor) -> torch.Tensor:
    """The block distance of every pixel to the block at offset ``(dy, dx)`` (B, m, H, W), summed as
    :func:`.refine_cpu._block_distance` sums it: depth differences row by row, then colour channel by channel."""
    bsz, _, h, w = depth.shape
    r = block_size // 2
    dt = torch.float64 if depth.dtype == torch.float64 else torch.float32
    nb = float(block_size * block_size)

    def pad(t):  # (B, C, H, W) -> (B, C, H+2r, W+2r): replicate by r
        return F.pad(t.detach().to(dt), (r,) * 4, mode="replicate")

    wp = w + 2 * r
    rows = torch.arange(h, device=depth.device).view(1, 1, h, 1)
    cols = torch.arange(w, device=depth.device).view(1, 1, 1, w)
    there = ((rows + dy) * wp + cols + dx).reshape(bsz, -1)  # the matched block's top-left corner, padded plane
    m = dy.shape[1]

    def pairs(plane):  # plane (B, H+2r, W+2r) -> per block pixel the pixel's value (B, 1, H, W), the match's (B, m, H, W)
        flat = plane.flatten(1)
        for u in range(block_size):
            for v in range(block_size):
                yield plane[:, None, u:u + h, v:v + w], flat.gather(1, there + (u * wp + v)).view(bsz, m, h, w)

    xp = pad(depth)[:, 0]
    tp = None if trust is None else pad(trust)[:, 0]
    num = torch.zeros(dy.shape, dtype=dt, device=depth.device)
    cnt = torch.zeros_like(num) if tp is not None else None
    t_pairs = pairs(tp) if tp is not None else None
    for a, b in pairs(xp):
        df = a - b
        if tp is None:
            num = num + df * df
        else:
            ta, tb = next(t_pairs)
            tt = ta * tb
            num = num + tt * (df * df)
            cnt = cnt + tt
    col = torch.zeros_like(num)
    ncol = 0 if rgb is None else rgb.shape[1]
    if ncol:
        cp = pad(rgb)
        for c in range(ncol):
            for a, b in pairs(cp[:, c]):
                dc = a - b
                col = col + dc * dc
    consts = rho.detach().to(device=depth.device, dtype=torch.float64).view(-1, 1, 1, 1)
    crho = (consts / (max(1, ncol) * nb)).to(dt)  # rounded once, as the kernel's constants are
    if tp is None:
        d = num * torch.full((), 1.0 / nb, dtype=dt, device=depth.device) + crho * col
    else:  # the kernel divides in float64 here (its ``max(cnt, 1)`` is a float64), and rounds when it stores
        d = (num.double() / cnt.double().clamp_min(1.0) + (crho * col).double()).to(dt)
    return torch.where(d > 0, d, torch.zeros_like(d))


def refine_torch(depth: torch.Tensor, rgb: Optional[torch.Tensor], trust: Optional[torch.Tensor],
                 previous_index: torch.Tensor, block_size: int, search_window: int, k: int, rho: torch.Tensor,
                 include_self: bool, lattice: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Top-k ``(dist, index)`` (B, k, H, W) among each pixel's previous matches and (``lattice > 0``) the offsets
    of the search window on a lattice of that step: :func:`.refine_cpu.refine_cpu` with ``reach = 0``."""
    bsz, _, h, w = depth.shape
    big_r = search_window // 2
    s = 2 * big_r + 1
    prev = previous_index.detach().to(torch.int64)
    pixel = torch.arange(h * w, device=depth.device).view(1, 1, h, w)
    dy = torch.div(prev, w, rounding_mode="floor") - torch.div(pixel, w, rounding_mode="floor")
    dx = prev % w - pixel % w
    oid = (dy + big_r) * s + dx + big_r
    rows, cols = torch.div(pixel, w, rounding_mode="floor"), pixel % w
    # in the window and in the image (a stream's kept matches can point elsewhere), as the CPU kernel checks
    usable = ((dy.abs() <= big_r) & (dx.abs() <= big_r) & (rows + dy >= 0) & (rows + dy < h) & (cols + dx >= 0)
              & (cols + dx < w))
    if not include_self:
        usable &= oid != big_r * s + big_r
    if lattice > 0:  # the lattice search scores these itself
        usable &= (dy % lattice != 0) | (dx % lattice != 0)
    dy, dx = dy.masked_fill(~usable, 0), dx.masked_fill(~usable, 0)  # scored as the pixel itself, then dropped
    dist = _rescored(depth, rgb, trust, dy, dx, block_size, rho)
    keys = encode_keys(dist, oid.masked_fill(~usable, 0), search_window).masked_fill(~usable, _INT64_MAX)
    if lattice > 0:
        searched = top_keys(depth, rgb, trust, block_size, search_window, k, rho, include_self, None, lattice)
        keys = torch.cat([searched, keys], dim=1)
    n = keys.shape[1]
    top = smallest_keys(keys.permute(0, 2, 3, 1).reshape(bsz, h * w, n), k)  # (B, H·W, k) ascending
    top = top.transpose(1, 2).reshape(bsz, k, h, w)
    # fewer than k candidates (previous matches that left the window): an infinite distance to the pixel itself
    none = encode_keys(torch.full((), float("inf"), dtype=dist.dtype, device=dist.device),
                       torch.full((), big_r * s + big_r, dtype=torch.int64, device=dist.device), search_window)
    return decode_keys(torch.where(top == _INT64_MAX, none, top), search_window, depth.dtype)
