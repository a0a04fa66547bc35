"""Fast approximate block matching from a previous set of matches (the re-matching layers of the model).

The unrolled model matches blocks on x⁰ and again on later estimates of the same scene. Between two
passes the estimate changes by a denoising step, and so do the matches, but mostly among blocks that
were already good candidates. :func:`refine_matches` therefore re-ranks, exactly, only some candidates:
the previous matches of the pixel (and, with ``reach > 0``, of its four neighbours at that distance, taken
at the same offset) and the window's offsets on a lattice of step ``lattice`` (searched by the exact kernel,
seeded with the re-scored previous matches). The defaults (``reach = 0``, ``lattice = 2``) are the model's.
"""
from __future__ import annotations

from typing import Optional

import torch

from .._checks import check_same_hw
from ..errors import DepthSRError, ShapeError
from ._common import BlockMatches, Scalar, finish, prepare
from ..native import host_kernel
from .refine_torch import refine_torch
from .torch_search import block_match_torch

__all__ = ["refine_matches"]


def refine_matches(
    depth: torch.Tensor,
    previous: BlockMatches,
    rgb: Optional[torch.Tensor] = None,
    trust: Optional[torch.Tensor] = None,
    block_size: int = 5,
    search_window: int = 21,
    k: int = 10,
    color_weight: Scalar = 1.0,
    temperature: Scalar = 1.0,
    include_self: bool = False,
    *,
    reach: int = 0,
    lattice: int = 2,
) -> BlockMatches:
    """The ``k`` best blocks among the previous matches and the offsets of a lattice of the window.

    Same distance, arguments and result as :func:`~torch_depth_sr.block_matching.block_match`; the
    candidates are the offsets of ``previous`` at the pixel (and at its 4 neighbours ``reach`` pixels away
    when ``reach > 0``) and, with ``lattice > 0``, every offset of the window whose ``dy`` and ``dx`` are
    multiples of ``lattice``, restricted to the search window. The
    result is the exact top-``k`` of those candidates, so it is never worse than the previous matches
    re-scored on ``depth``. On the CPU a numba kernel runs; elsewhere (or without numba) the same candidates are
    ranked in torch (:mod:`.refine_torch`), but for ``reach > 0``, where the exact search runs instead (a superset
    of the candidates). Before 2026-12-04 the exact search ran off the CPU for every ``reach``: the default tier's
    GPU output was 6 % worse in RMSE than its CPU output on the speed track's frames.

    Examples:
        >>> from torch_depth_sr.block_matching import block_match
        >>> x, rgb = torch.rand(1, 1, 24, 32), torch.rand(1, 3, 24, 32)
        >>> first = block_match(x, rgb, None, block_size=3, search_window=9, k=4)
        >>> again = refine_matches(x, first, rgb, None, block_size=3, search_window=9, k=4)
        >>> bool(torch.equal(again.index, first.index))  # same image: the same matches
        True
    """
    rho, temp = prepare(depth, rgb, trust, block_size, search_window, k, color_weight, temperature,
                        include_self, 1)
    if not isinstance(previous, BlockMatches):
        raise DepthSRError(f"previous must be BlockMatches (from block_match); got {type(previous).__name__}.")
    check_same_hw(depth, previous.index, "depth", "previous matches",
                  "Pass the matches block_match returned for this depth map.")
    if previous.index.shape[1] < k:
        raise ShapeError(f"previous matches {tuple(previous.index.shape)} must be (B, >= k, H, W) for depth "
                         f"{tuple(depth.shape)} and k={k}.", actual=tuple(previous.index.shape),
                         expected=f"(B, >= {k}, H, W)")
    if isinstance(reach, bool) or not isinstance(reach, int) or reach < 0:
        raise DepthSRError(f"reach must be an int >= 0; got {reach!r}.")
    refine_cpu = host_kernel("block_matching.refine_cpu", "refine_cpu", depth.detach(), dtypes=None)  # no gradient
    with torch.no_grad():
        trust = None if trust is None else trust.to(depth.dtype)
        rgb = None if rgb is None else rgb.to(depth.dtype)
        if refine_cpu is None and reach == 0:  # the same candidates in torch: off the CPU or without numba
            dist, index = refine_torch(depth, rgb, trust, previous.index, block_size, search_window, k, rho.detach(),
                                       include_self, lattice)
            return finish(dist, index, temp)
        if refine_cpu is None:  # neighbours' matches have no torch form: the exact search, a superset of them
            dist, index = block_match_torch(depth, rgb, trust, block_size, search_window, k, rho.detach(),
                                            include_self, None, 1)
            return finish(dist, index, temp)
        dist, index = refine_cpu(depth, rgb, trust, previous.index, block_size, search_window, k,
                                         rho, include_self, reach, lattice)
    return finish(dist, index, temp)
