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
``(dy + S//2)·S + (dx + S//2)`` (row-major over the window). The weights are
``ω_ij = softmax_j(−d(i, j) / h)`` over the kept blocks.

Layout of the package:

* ``_common.py`` — the result type, argument checks, offset ids and weights;
* ``reference.py`` — :func:`block_match_reference`, the unfold oracle (tests, small images);
* ``cpu_exact.py`` — the exact search on the CPU, a numba kernel (running top-k over the window), of the whole
  image or of some pixels (:func:`block_match_at`);
* ``torch_search.py`` — the exact search on any device, in torch (GPU; CPU when numba is missing);
* ``refine.py`` / ``refine_cpu.py`` / ``refine_torch.py`` — :func:`refine_matches`, the re-matching search: the
  previous matches, optionally the neighbours' (PatchMatch propagation) and the window's offsets on a lattice,
  ranked exactly; the CPU kernel and its torch twin for the other devices (the same candidates).

The numba kernels are loaded by :mod:`torch_depth_sr.native` (one warning per process without numba).

Reference: Y. Yang et al., "depth maps restoration based on the sparse representation of nonlocal
self-similarity" (the paper under ``shared/paper``), §II-B.
"""
from __future__ import annotations

from typing import Optional

import torch

from .._checks import check_4d, check_same_hw
from ..errors import DepthSRError
from ._common import BlockMatches, Scalar, finish, prepare
from ..native import cpu_kernel, host_path
from .reference import block_match_reference
from .refine import refine_matches
from .torch_search import block_match_torch

__all__ = ["BlockMatches", "block_match", "block_match_at", "block_match_reference", "refine_matches",
           "gather_neighbors"]

BACKENDS = ("auto", "numba", "torch")


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
    """The ``k`` most similar blocks to the block around every pixel: the exact search of the window.

    .. math::

        d(i, j) = \\frac{\\sum_p t_i(p) t_j(p) (x_i(p) - x_j(p))^2}{\\max(1, \\sum_p t_i(p) t_j(p))}
                  + \\rho\\, \\operatorname{mean}_{p,c} (c_i(p) - c_j(p))^2,
        \\qquad \\omega_{ij} = \\operatorname{softmax}_j(-d(i, j) / h)

    Candidates ``j`` lie in the ``S×S`` search window around ``i`` and inside the image; block pixels
    outside the image are replicate-padded. Computed without gradient; equal (to float round-off) to
    :func:`block_match_reference`. Distances are computed in the input's precision.

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
        backend: ``"auto"`` (the numba kernel on CPU, torch elsewhere), ``"numba"`` or ``"torch"``.

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
    rho, temp = prepare(depth, rgb, trust, block_size, search_window, k, color_weight, temperature,
                        include_self, search_stride)
    if backend not in BACKENDS:
        raise DepthSRError(f"backend must be one of {BACKENDS}; got {backend!r}.")
    if chunk_rows is not None and (isinstance(chunk_rows, bool) or not isinstance(chunk_rows, int)
                                   or chunk_rows < 1):
        raise DepthSRError(f"chunk_rows must be None or an int >= 1; got {chunk_rows!r}.")
    on_cpu = depth.device.type == "cpu"
    exact_cpu = (cpu_kernel("block_matching.cpu_exact", "block_match_cpu_exact", required=backend == "numba")
                 if host_path(depth.device) and backend != "torch" else None)  # numba (torch_depth_sr.native loads it)
    if backend == "numba" and not on_cpu:
        raise DepthSRError(f"backend='numba' runs on the CPU; depth is on {depth.device}. Use 'auto' or 'torch'.")
    with torch.no_grad():
        if trust is not None:
            trust = trust.to(depth.dtype)
        if rgb is not None:
            rgb = rgb.to(depth.dtype)
        args = (depth, rgb, trust, block_size, search_window, k, rho.detach(), include_self, chunk_rows,
                search_stride)
        if exact_cpu is not None:
            dist, index = exact_cpu(*args)
        else:
            dist, index = block_match_torch(*args)
    return finish(dist.to(depth.device), index.to(depth.device), temp)


def block_match_at(depth: torch.Tensor, rgb: Optional[torch.Tensor], trust: Optional[torch.Tensor],
                   where: torch.Tensor, dist: torch.Tensor, index: torch.Tensor, block_size: int = 5,
                   search_window: int = 21, color_weight: Scalar = 1.0, include_self: bool = False) -> bool:
    """:func:`block_match`'s exact search at the pixels ``where`` (B, 1, H, W) bool alone, their ``k`` matches
    (``k = dist.shape[1]``) written into ``dist`` and ``index`` (B, k, H, W) in place, the other pixels' left as they
    are: the matches a stream keeps where its scene has not changed, searched again where it has. Each written pixel
    gets the whole image's matches bit for bit (its rows and block sums are the whole image's, not a crop's).

    Only by the numba kernel on the CPU, into C-contiguous ``dist`` of ``depth``'s dtype (float32 or float64) and
    int64 ``index``: returns False and writes nothing otherwise (the caller searches another way).

    Examples:
        >>> depth, rgb = torch.rand(1, 1, 24, 32), torch.rand(1, 3, 24, 32)
        >>> m = block_match(depth, rgb, None, block_size=3, search_window=7, k=4)
        >>> dist, index = torch.zeros_like(m.dist), torch.zeros_like(m.index)
        >>> where = torch.zeros(1, 1, 24, 32, dtype=torch.bool)
        >>> where[..., 5:9, 10:20] = True
        >>> block_match_at(depth, rgb, None, where, dist, index, block_size=3, search_window=7)
        True
        >>> bool(torch.equal(index[where.expand_as(index)], m.index[where.expand_as(index)]))
        True
    """
    b, _, h, w = depth.shape
    k = dist.shape[1]
    rho, _ = prepare(depth, rgb, trust, block_size, search_window, k, color_weight, 1.0, include_self, 1)
    if (not host_path(depth.device) or depth.dtype not in (torch.float32, torch.float64) or dist.dtype != depth.dtype
            or index.dtype != torch.int64 or dist.shape != (b, k, h, w) or index.shape != dist.shape
            or where.shape != (b, 1, h, w) or not (dist.is_contiguous() and index.is_contiguous())):
        return False
    kernel = cpu_kernel("block_matching.cpu_exact", "block_match_cpu_exact_at", required=False)
    if kernel is None:
        return False
    with torch.no_grad():
        trust = None if trust is None else trust.to(depth.dtype)
        rgb = None if rgb is None else rgb.to(depth.dtype)
        kernel(depth.detach(), rgb, trust, where.to(torch.bool), dist, index, block_size, search_window, k,
               rho.detach(), include_self)
    return True


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
    check_same_hw(values, index, "values", "index", "Gather with the matches of an image of the values' size.")
    b, c, h, w = values.shape
    k = index.shape[1]
    flat = values.reshape(b, c, h * w)  # (B, C, HW)
    idx = index.reshape(b, 1, k * h * w).expand(b, c, k * h * w)  # (B, C, k·HW)
    return torch.gather(flat, 2, idx).view(b, c, k, h, w)  # (B, C, k, H, W)
