"""The nonlocal terms: the gradient estimate α (paper §II-B) and the value prior (beyond the paper).

.. math::

    \\alpha_i = \\sum_{m=1}^{k} \\omega_{i m}\\, (D x)_{j_m(i)}

where ``j_m(i)`` is the centre of the ``m``-th block most similar to the block around ``i`` and
``ω`` the block-matching weights. ``η‖Dx − α‖₁`` then pulls the gradient at ``i`` towards the
gradients at similar places (like NCSR's centralised sparsity). :func:`nonlocal_value_prior` uses the
matched centres' values; :func:`nonlocal_terms` computes both from one read of the matches (one gather on
the torch path, a numba kernel on the CPU when no gradient is needed).
"""
from __future__ import annotations

from typing import Optional, Tuple, Union

import torch

from ._checks import check_4d, check_same_shape
from .block_matching import BlockMatches, gather_neighbors
from .native import cpu_kernel, host_kernel, host_path, on_device

__all__ = ["nonlocal_gradient", "nonlocal_terms", "nonlocal_value_prior"]

_SAME_MATCHES = "Both are (B,k,H,W), from one block matching call."


def nonlocal_gradient(grad_x: torch.Tensor, matches: BlockMatches) -> torch.Tensor:
    """α_i = Σ_m ω[m, i] · grad_x[index[m, i]]: the weighted mean of the gradients at matched centres.

    Differentiable with respect to ``grad_x`` (a gather and a weighted sum) and to ``matches.weight``;
    the indices carry no gradient. On the CPU without gradient, for ``C = 2``, by a numba kernel with
    :func:`nonlocal_terms`' arithmetic (the same α; :mod:`~torch_depth_sr.nonlocal_kernel`).

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
    check_same_shape(matches.weight, matches.index, "matches.weight", "matches.index", _SAME_MATCHES)
    same_grid = matches.index.shape[0] == grad_x.shape[0] and matches.index.shape[2:] == grad_x.shape[2:]
    if grad_x.shape[1] == 2 and same_grid:
        kernel = host_kernel("nonlocal_kernel", "nonlocal_gradient_cpu", grad_x, matches.weight)
        if kernel is not None:
            return kernel(grad_x, matches.index, matches.weight)
    neigh = gather_neighbors(grad_x, matches.index)  # (B, C, k, H, W)
    w = matches.weight.to(grad_x.dtype).unsqueeze(1)  # (B, 1, k, H, W)
    return (w * neigh).sum(dim=2)  # (B, C, H, W)


def _value_prior(xbar, var, offset2, weight: float, max_var: float, max_offset: float):
    agree = (var.detach() < max_var) & (offset2.detach() <= max_offset ** 2)
    return weight * agree.to(xbar.dtype), xbar


def _match_offsets(index: torch.Tensor, like: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
    """Row and column offsets ``j − i`` of the matched centres, each ``(B,k,H,W)`` in ``like``'s dtype."""
    h, wd = like.shape[-2:]
    rows = torch.arange(h, device=like.device, dtype=like.dtype).view(1, 1, h, 1)
    cols = torch.arange(wd, device=like.device, dtype=like.dtype).view(1, 1, 1, wd)
    oy = torch.div(index, wd, rounding_mode="floor").to(like.dtype) - rows
    ox = (index % wd).to(like.dtype) - cols
    return oy, ox


def _value_statistics(xj: torch.Tensor, w: torch.Tensor, index: torch.Tensor, ridge: float):
    """``(x̄, variance, |centroid|²)`` of the matched values ``xj (B,k,H,W)`` with weights ``w``.

    ``ridge = 0``: x̄ is the weighted mean. ``ridge > 0``: x̄ is the value at the pixel of the plane
    ``x_j ≈ a + g·(j − i)`` fitted by weighted least squares with ``ridge·|g|²`` added (px²: where the matched
    centres do not spread in two directions the slope falls back towards 0), and the variance is the residuals'.
    """
    sw = w.sum(1, keepdim=True)
    empty = sw <= 1e-12  # no centre left (range weights): no estimate, never passes the variance gate
    wn = w / sw.clamp_min(torch.finfo(w.dtype).tiny)
    oy, ox = _match_offsets(index, xj)
    xbar = (wn * xj).sum(1, keepdim=True)
    cy, cx = (wn * oy).sum(1, keepdim=True), (wn * ox).sum(1, keepdim=True)
    d = xj - xbar
    var = (wn * d * d).sum(1, keepdim=True)
    offset2 = cy.square() + cx.square()
    var = torch.where(empty, torch.full_like(var, float("inf")), var)
    if ridge <= 0:
        return xbar, var, offset2
    ey, ex = oy - cy, ox - cx
    syy, sxx, syx = ((wn * a * b_).sum(1, keepdim=True) for a, b_ in ((ey, ey), (ex, ex), (ey, ex)))
    syv, sxv = (wn * ey * d).sum(1, keepdim=True), (wn * ex * d).sum(1, keepdim=True)
    a11, a22 = syy + ridge, sxx + ridge
    det = a11 * a22 - syx * syx
    gy = (a22 * syv - syx * sxv) / det
    gx = (a11 * sxv - syx * syv) / det
    res = var - 2 * (gy * syv + gx * sxv) + gy * gy * syy + 2 * gy * gx * syx + gx * gx * sxx
    res = torch.where(empty, torch.full_like(res, float("inf")), res.clamp_min(0))
    return xbar - (gy * cy + gx * cx), res, offset2


def nonlocal_value_prior(x: torch.Tensor, matches: BlockMatches, weight: float, max_var: float,
                         max_offset: float = 2.5, plane_ridge: float = 0.0) -> Tuple[torch.Tensor, torch.Tensor]:
    """``(W, x̄)``: a nonlocal estimate x̄ of each pixel's value from its matched centres, and a weight map.

    The paper uses the matched blocks for gradients only (α). Their centre *values* are a nonlocal-means
    estimate of the depth itself, trusted (W = η₃) only where the centres' values agree (weighted variance
    below ``max_var`` noise σ², the units of ``x``) and their weighted centroid lies within ``max_offset``
    pixels: where the centres straddle an edge x̄ would blur it, and where they all lie on one side (image
    borders) it is biased on any slope (Σ w (x_i + g·d) = x_i only when Σ w d = 0). Carrying each centre along
    the nonlocal gradient α instead was tried and blurred edges (α is large there). Adds η₃/2 ‖x − x̄‖² on
    those pixels to the x-subproblem.
    """
    _, diag, target = nonlocal_terms(x, None, matches, value_weight=weight, max_var=max_var, max_offset=max_offset,
                                     plane_ridge=plane_ridge)
    return diag, target


def _kernel():
    """The numba kernel, or None (see :mod:`torch_depth_sr.native`)."""
    return cpu_kernel("nonlocal_kernel", "nonlocal_terms_cpu")


def nonlocal_terms(x: torch.Tensor, grad_x: Optional[torch.Tensor], matches: BlockMatches, *,
                   value_weight: float = 0.0, max_var: float = 0.25, max_offset: float = 2.5,
                   plane_ridge: float = 0.0, range_sigma: Union[float, torch.Tensor, None] = None,
                   region: Optional[torch.Tensor] = None, backend: str = "auto"
                   ) -> Tuple[Optional[torch.Tensor], Optional[torch.Tensor], Optional[torch.Tensor]]:
    """α, and the value prior ``(W, x̄)``, from one read of the matches.

    Args:
        x: ``(B,1,H,W)`` current estimate.
        grad_x: ``(B,2,H,W)`` its gradient ``D x``, or None (no α).
        matches: :class:`~torch_depth_sr.block_matching.BlockMatches` of ``x``, weights included.
        value_weight, max_var, max_offset: the value prior's η₃ and gates (:func:`nonlocal_value_prior`);
            ``value_weight = 0`` skips it.
        plane_ridge: 0: x̄ is the matched centres' weighted mean; > 0: the value at the pixel of a plane fitted
            to them (unbiased on slopes wherever the centres lie), the variance gate then reads the residuals.
        range_sigma: None, or a float or ``(B,1,H,W)`` map r: each centre of the value prior is also weighed by
            exp(−(x_j − x_i)²/2r²) (an edge-stopping range kernel on the current estimate, as the rolling-guidance
            filter's) where r > 0; α keeps the match weights.
        region: None, or a ``(B,1,H,W)`` bool map of the pixels whose outputs are wanted: the numba kernel computes
            those alone (0 elsewhere), the torch path every pixel.
        backend: ``"auto"`` (the numba kernel for float CPU tensors when no gradient is needed, else torch),
            ``"torch"``.

    Returns:
        ``(α or None, W or None, x̄ or None)``; differentiable in ``x``, ``grad_x`` and ``matches.weight``
        (W carries none: it is a 0/η₃ mask).

    Examples:
        >>> from torch_depth_sr.block_matching import block_match
        >>> from torch_depth_sr.operators import grad
        >>> x = torch.rand(1, 1, 16, 16)
        >>> m = block_match(x, None, None, block_size=3, search_window=7, k=4)
        >>> alpha, diag, target = nonlocal_terms(x, grad(x), m, value_weight=10.0)
        >>> alpha.shape, diag.shape, target.shape
        (torch.Size([1, 2, 16, 16]), torch.Size([1, 1, 16, 16]), torch.Size([1, 1, 16, 16]))
    """
    if backend not in ("auto", "torch"):
        raise ValueError(f"backend must be 'auto' or 'torch'; got {backend!r}.")
    check_4d(x, "x", channels=1)
    if grad_x is not None:
        check_4d(grad_x, "grad_x", channels=2)
    check_same_shape(matches.weight, matches.index, "matches.weight", "matches.index", _SAME_MATCHES)
    value = value_weight > 0
    if grad_x is None and not value:
        return None, None, None
    tracked = torch.is_grad_enabled() and (x.requires_grad or matches.weight.requires_grad
                                           or (grad_x is not None and grad_x.requires_grad))
    if range_sigma is not None:
        range_sigma = on_device(range_sigma, x.dtype, x.device)
    kernel = None
    if backend == "auto" and not tracked and host_path(x.device) and x.dtype in (torch.float32, torch.float64):
        kernel = _kernel()
    if kernel is not None:
        alpha, xbar, var, offset2 = kernel(x, grad_x, matches.index, matches.weight, plane_ridge, range_sigma, region)
    else:
        w = matches.weight.to(x.dtype)  # (B, k, H, W)
        planes = x if grad_x is None else torch.cat([grad_x, x], dim=1)  # one gather for α and x̄
        neigh = gather_neighbors(planes, matches.index)  # (B, C, k, H, W)
        alpha = None if grad_x is None else (w.unsqueeze(1) * neigh[:, :2]).sum(dim=2)  # (B, 2, H, W)
        if not value:
            return alpha, None, None
        xj = neigh[:, -1]
        if range_sigma is None:
            wv = w
        else:
            rs = range_sigma
            ratio = torch.where(rs > 0, (xj - x) / rs.clamp_min(torch.finfo(x.dtype).tiny), torch.zeros_like(xj))
            wv = w * torch.exp(-0.5 * ratio ** 2)
        xbar, var, offset2 = _value_statistics(xj, wv, matches.index, plane_ridge)
    if not value:
        return alpha, None, None
    diag, target = _value_prior(xbar, var, offset2, value_weight, max_var, max_offset)
    return alpha, diag, target
