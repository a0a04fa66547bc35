"""What every block-matching path shares: the result type, argument checks, offsets and weights."""
from __future__ import annotations

from typing import NamedTuple, Optional, Union

import numpy as np
import torch

from .._checks import check_4d, check_floating, check_min_size, check_per_sample, check_same_hw
from ..errors import DepthSRError, ShapeError
from ..native import host_path

__all__ = ["BlockMatches", "candidates_everywhere", "lattice", "prepare", "finish", "index_from_offsets", "offset_order",
           "symmetric_order"]

Scalar = Union[float, torch.Tensor]

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



def lattice(radius: int, stride: int) -> list[int]:
    """Offsets ``-radius..radius`` that are multiples of ``stride`` (0 always included)."""
    return [o for o in range(-radius, radius + 1) if o % stride == 0]


def _min_valid_offsets(size: int, radius: int, stride: int) -> int:
    """Smallest number of in-image lattice offsets along one axis, over all positions."""
    offs = np.array(lattice(radius, stride))
    pos = np.arange(size)[:, None] + offs[None, :]
    return int(((pos >= 0) & (pos < size)).sum(1).min())


def _per_sample(value: Scalar, name: str, batch: int, positive: bool) -> torch.Tensor:
    """A float or (B,)/(1,)/() tensor as a (B,) tensor; checks the sign."""
    if isinstance(value, torch.Tensor):
        check_per_sample(value, name, batch)
        v = value.reshape(-1).expand(batch) if value.numel() == 1 else value.reshape(batch)
    else:
        try:
            v = torch.full((batch,), float(value), dtype=torch.float64)
        except (TypeError, ValueError):
            raise DepthSRError(f"{name} must be a float or a (B,) tensor; got {type(value).__name__}.") from None
    vd = v.detach()
    if not host_path(vd.device):  # a tensor off the CPU is not read: that would make the host wait for the device
        return v
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
            raise ShapeError(f"rgb must have at least one channel; got shape {tuple(rgb.shape)}.",
                             actual=tuple(rgb.shape), expected="(B,C,H,W) with C >= 1")
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
    check_min_size(depth, "depth", block_size, f"one {block_size}x{block_size} block; use a smaller block_size")


def candidates_everywhere(h: int, w: int, search_window: int, include_self: bool, search_stride: int = 1) -> int:
    """The number of candidate blocks that every pixel of an ``h×w`` image has (the image corner's share of the
    window): the largest ``k`` a search can return there.

    Examples:
        >>> candidates_everywhere(100, 100, 15, include_self=False), candidates_everywhere(6, 6, 15, False)
        (63, 35)
    """
    radius = search_window // 2
    n_min = _min_valid_offsets(h, radius, search_stride) * _min_valid_offsets(w, radius, search_stride)
    return n_min - (0 if include_self else 1)


def _check_k(k, h, w, search_window, search_stride, include_self):
    n_min = candidates_everywhere(h, w, search_window, include_self, search_stride)
    if k > n_min:
        raise DepthSRError(
            f"k={k} is larger than the number of candidate blocks available at every pixel ({n_min} at the "
            f"image corner for search_window={search_window}, search_stride={search_stride}, "
            f"include_self={include_self}, image {h}x{w}). Use k <= {n_min} or a larger search_window.")


def prepare(depth: torch.Tensor, rgb: Optional[torch.Tensor], trust: Optional[torch.Tensor], block_size: int,
            search_window: int, k: int, color_weight: Scalar, temperature: Scalar, include_self: bool,
            search_stride: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Check the arguments shared by every search; return ``(rho, temperature)`` as ``(B,)`` tensors."""
    _validate(depth, rgb, trust, block_size, search_window, k, search_stride)
    b, _, h, w = depth.shape
    _check_k(k, h, w, search_window, search_stride, include_self)
    rho = _per_sample(color_weight, "color_weight", b, positive=False)
    temp = _per_sample(temperature, "temperature", b, positive=True)
    return rho, temp


def finish(dist: torch.Tensor, index: torch.Tensor, temp: torch.Tensor) -> BlockMatches:
    """Weights = softmax(−dist/h) over k (differentiable in a tensor temperature)."""
    t = temp.to(device=dist.device, dtype=dist.dtype).view(-1, 1, 1, 1)
    weight = torch.softmax(-dist / t, dim=1)
    return BlockMatches(dist, index, weight)


def index_from_offsets(oid: torch.Tensor, search_window: int, h: int, w: int) -> torch.Tensor:
    """Offset ids ``(dy+R)·S + (dx+R)`` at pixel (i, j) → flat index ``(i+dy)·W + (j+dx)`` (int64).

    Uses a lookup table ``dy·W + dx`` and one in-place add, so the only large allocation is the result.
    """
    r = search_window // 2
    offs = torch.arange(-r, r + 1, device=oid.device)
    lut = (offs.view(-1, 1) * w + offs.view(1, -1)).reshape(-1)  # (S²,) int64
    index = lut[oid.long()]  # (B, k, H, W)
    index += torch.arange(h * w, device=oid.device).view(1, 1, h, w)
    return index



def offset_order(search_window: int, stride: int, include_self: bool) -> np.ndarray:
    """Offset ids of the lattice, nearest to the centre first (ties by id)."""
    big_r = search_window // 2
    offs = [((dy * dy + dx * dx), (dy + big_r) * search_window + dx + big_r)
            for dy in lattice(big_r, stride) for dx in lattice(big_r, stride)
            if include_self or dy != 0 or dx != 0]
    return np.array([o for _, o in sorted(offs)], dtype=np.int32)


def symmetric_order(order: np.ndarray, search_window: int) -> tuple[np.ndarray, np.ndarray]:
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

