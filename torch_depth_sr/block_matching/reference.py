"""The unfold oracle: every candidate block formed explicitly. Slow and memory hungry, obviously correct."""
from __future__ import annotations

import math
from typing import Optional

import torch
import torch.nn.functional as F

from ._common import Scalar, BlockMatches, finish, index_from_offsets, prepare

__all__ = ["block_match_reference"]


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
    rho, temp = prepare(depth, rgb, trust, block_size, search_window, k, color_weight, temperature,
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
        index = index_from_offsets(order, search_window, h, w)
    return finish(sd, index, temp)
