r"""CG solves with an implicit-differentiation backward.

For ``x = A(θ)⁻¹ b`` with ``A`` symmetric, a loss ``L(x)`` with upstream gradient
``ḡ = ∂L/∂x`` has

.. math::

    g = A^{-1} \bar g, \qquad \frac{\partial L}{\partial b} = g, \qquad
    \frac{\partial L}{\partial θ} = -\frac{\partial}{\partial θ} \langle g, A(θ)\, x\rangle
    \Big|_{x,\,g\ \text{fixed}} .

The forward CG runs under ``no_grad`` and the backward is one more CG solve with the same
operator, so memory does not grow with the number of CG iterations (unlike unrolled
backpropagation through the loop). The gradient is exact only up to the CG tolerance of both solves.
Reference: the implicit function theorem, as in deepinv's ``least_squares`` / ``conjugate_gradient``
implicit backward.
"""
from __future__ import annotations

from typing import Sequence

import torch
from torch.autograd.function import once_differentiable

from ..errors import DepthSRError
from .cg import CGResult, Operator, conjugate_gradient

__all__ = ["cg_solve"]


class _ImplicitCG(torch.autograd.Function):
    """``x = A⁻¹ b``; the parameter tensors are inputs (so autograd routes their gradients) and are
    also carried in ``settings`` because the backward differentiates ``apply_A``, which closes over
    those very objects."""

    @staticmethod
    def forward(ctx, b, x0, settings, *params):  # type: ignore[override]
        apply_A, precond, tol, max_iter, param_refs, early_exit, _ = settings
        res = conjugate_gradient(apply_A, b, x0=x0, precond=precond, tol=tol, max_iter=max_iter, early_exit=early_exit)
        x = res.x
        if x is x0 or x is b:  # never return an input object as an output
            x = x.clone()
        ctx.settings = settings
        ctx.save_for_backward(x)
        ctx.mark_non_differentiable(res.iterations, res.residual, res.history)
        return x, res.iterations, res.residual, res.history

    @staticmethod
    @once_differentiable
    def backward(ctx, grad_x, *_unused):  # type: ignore[override]
        apply_A, precond, tol, _, param_refs, _, backward_max_iter = ctx.settings
        (x,) = ctx.saved_tensors
        n_params = len(param_refs)
        if grad_x is None:
            return (None, None, None) + (None,) * n_params
        # g = A⁻¹ ḡ  (A symmetric)
        g = conjugate_gradient(apply_A, grad_x, precond=precond, tol=tol, max_iter=backward_max_iter).x
        grad_b = g if ctx.needs_input_grad[0] else None
        param_grads: list = [None] * n_params
        wanted = [i for i in range(n_params) if ctx.needs_input_grad[3 + i]]
        if wanted:
            with torch.enable_grad():
                ax = apply_A(x.detach())  # graph from the parameters to A x
                if ax.requires_grad:
                    grads = torch.autograd.grad(ax, [param_refs[i] for i in wanted], grad_outputs=-g, allow_unused=True)
                    for i, gr in zip(wanted, grads):
                        param_grads[i] = gr
        return (grad_b, None, None) + tuple(param_grads)


def cg_solve(
    apply_A: Operator,
    b: torch.Tensor,
    x0: torch.Tensor | None = None,
    precond: Operator | None = None,
    tol: float = 1e-5,
    max_iter: int = 100,
    implicit: bool = True,
    params: Sequence[torch.Tensor] = (),
    *,
    early_exit: bool = True,
    backward_max_iter: int | None = None,
) -> CGResult:
    r"""Solve ``A x = b`` (``A`` SPD) by batched CG, differentiable in ``b`` and in ``A``'s parameters.

    With ``implicit=True`` the forward runs :func:`~torch_depth_sr.solvers.cg.conjugate_gradient`
    under ``no_grad`` inside an ``autograd.Function``; the backward solves ``A g = ∂L/∂x`` with the
    same CG settings and returns ``g`` as the gradient of ``b`` and, for every tensor in ``params``,
    the vector-Jacobian product of ``−⟨g, A(x)⟩`` (``apply_A`` is re-evaluated at the detached ``x``
    with gradients enabled). ``apply_A`` must therefore be a deterministic closure over the tensors
    listed in ``params``: a tensor that ``A`` depends on but that is not listed gets **no gradient**
    (silently). List either the tensors ``apply_A`` uses or their ancestors, not both (that would
    count the gradient twice). ``x0`` receives no gradient (the solution does not depend on it).
    Double backward is not supported.

    With ``implicit=False`` CG runs with autograd tracking: exact gradients of the truncated
    iteration (unrolled backpropagation), memory growing with the number of iterations; ``params``
    is then used only when no CG step runs (the warm start ``x0`` already meets ``tol``, or
    ``max_iter=0``): the result is then differentiated implicitly, so it still depends on ``b`` and ``params``.

    Args:
        apply_A: function ``v ↦ A v`` (symmetric positive definite, sample-wise).
        b: right-hand side ``(B, ...)``, usually ``(B, C, H, W)``.
        x0: warm start (default zeros).
        precond: ``r ↦ M r`` with ``M ≈ A⁻¹`` SPD, or ``None``.
        tol: relative residual tolerance of both the forward and the backward solve.
        max_iter: maximum iterations of each solve.
        implicit: implicit-differentiation backward (``True``) or unrolled (``False``).
        params: tensors inside ``apply_A`` that should receive gradients (implicit mode).
        early_exit: of the forward solve (see :func:`~torch_depth_sr.solvers.cg.conjugate_gradient`); False runs
            ``max_iter`` iterations with no host synchronisation.
        backward_max_iter: maximum iterations of the implicit backward's solve, which always stops at ``tol``
            (default ``max_iter``).

    Returns:
        :class:`~torch_depth_sr.solvers.cg.CGResult`; only ``x`` carries gradient.

    Examples:
        >>> from torch_depth_sr.operators import laplacian
        >>> mu = torch.tensor(2.0, dtype=torch.float64, requires_grad=True)
        >>> b = torch.randn(2, 1, 6, 6, dtype=torch.float64, requires_grad=True)
        >>> res = cg_solve(lambda v: v + mu * laplacian(v), b, tol=1e-10, max_iter=200, params=(mu,))
        >>> res.x.sum().backward()
        >>> b.grad.shape, mu.grad is not None
        (torch.Size([2, 1, 6, 6]), True)
    """
    params = tuple(params)
    for i, p in enumerate(params):
        if not isinstance(p, torch.Tensor):
            raise DepthSRError(f"params[{i}] must be a torch.Tensor that apply_A uses; got {type(p).__name__}.")
    needs_grad = torch.is_grad_enabled() and (
        (isinstance(b, torch.Tensor) and b.requires_grad) or any(p.requires_grad for p in params)
    )
    backward_max_iter = max_iter if backward_max_iter is None else backward_max_iter
    if not implicit:
        res = conjugate_gradient(apply_A, b, x0=x0, precond=precond, tol=tol, max_iter=max_iter, early_exit=early_exit)
        if needs_grad and not res.x.requires_grad:
            # No CG step ran (the detached warm start already met ``tol``, or max_iter=0), so the unrolled
            # loop recorded no graph; x0 is the solution to tolerance, so differentiate it implicitly.
            return _implicit(apply_A, b, x0, precond, tol, max_iter, params, early_exit, backward_max_iter)
        return res
    if not needs_grad:
        with torch.no_grad():
            return conjugate_gradient(apply_A, b, x0=x0, precond=precond, tol=tol, max_iter=max_iter,
                                      early_exit=early_exit)
    return _implicit(apply_A, b, x0, precond, tol, max_iter, params, early_exit, backward_max_iter)


def _implicit(apply_A: Operator, b: torch.Tensor, x0: torch.Tensor | None, precond: Operator | None, tol: float,
              max_iter: int, params: tuple, early_exit: bool = True, backward_max_iter: int | None = None) -> CGResult:
    x0_detached = x0.detach() if isinstance(x0, torch.Tensor) else x0
    settings = (apply_A, precond, tol, max_iter, params, early_exit,
                max_iter if backward_max_iter is None else backward_max_iter)
    x, iterations, residual, history = _ImplicitCG.apply(b, x0_detached, settings, *params)
    return CGResult(x=x, iterations=iterations, residual=residual, history=history)
