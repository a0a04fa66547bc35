"""Nonlocal estimate of the gradient (paper §II-B): the weighted mean over the matched blocks.

.. math::

    \\alpha_i = \\sum_{m=1}^{k} \\omega_{i m}\\, (D x)_{j_m(i)}

where ``j_m(i)`` is the centre of the ``m``-th block most similar to the block around ``i`` and
``ω`` the block-matching weights. ``η‖Dx − α‖₁`` then pulls the gradient at ``i`` towards the
gradients at similar places (like NCSR's centralised sparsity).
"""
from __future__ import annotations

import torch

from ._checks import check_4d
from .block_matching import BlockMatches, gather_neighbors
from .errors import ShapeError

__all__ = ["nonlocal_gradient"]


def nonlocal_gradient(grad_x: torch.Tensor, matches: BlockMatches) -> torch.Tensor:
    """α_i = Σ_m ω[m, i] · grad_x[index[m, i]]: the weighted mean of the gradients at matched centres.

    Differentiable with respect to ``grad_x`` (a gather and a weighted sum) and to ``matches.weight``;
    the indices carry no gradient.

    Args:
        grad_x: ``(B, C, H, W)`` gradient field (``C = 2`` for ``D x``; any ``C`` works).
        matches: :class:`~torch_depth_sr.block_matching.BlockMatches` with ``(B, k, H, W)`` fields.

    Returns:
        ``(B, C, H, W)`` tensor ``α``.

    Examples:
        >>> from torch_depth_sr.block_matching import block_match
        >>> x = torch.rand(1, 1, 16, 16)
        >>> m = block_match(x, None, None, block_size=3, search_window=7, k=4)
        >>> gx = torch.randn(1, 2, 16, 16, requires_grad=True)
        >>> alpha = nonlocal_gradient(gx, m)
        >>> alpha.shape
        torch.Size([1, 2, 16, 16])
    """
    check_4d(grad_x, "grad_x")
    if matches.index.shape != matches.weight.shape:
        raise ShapeError(f"matches.index {tuple(matches.index.shape)} and matches.weight "
                         f"{tuple(matches.weight.shape)} must have the same shape (B,k,H,W).")
    neigh = gather_neighbors(grad_x, matches.index)  # (B, C, k, H, W)
    w = matches.weight.to(grad_x.dtype).unsqueeze(1)  # (B, 1, k, H, W)
    return (w * neigh).sum(dim=2)  # (B, C, H, W)
