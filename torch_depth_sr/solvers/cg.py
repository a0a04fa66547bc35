r"""Batched preconditioned conjugate gradients for symmetric positive definite systems.

Solves ``A x = b`` independently for every sample of a batch, where ``A`` is given as a function
``apply_A`` acting on the whole batch. Dot products are per sample (over all non-batch dims),
each sample has its own step sizes and its own stopping test, and a converged sample stops
changing while the others continue. Reference: Hestenes & Stiefel (1952); Saad, *Iterative
Methods for Sparse Linear Systems*, Alg. 9.1 (preconditioned CG).

With a preconditioner ``M ≈ A⁻¹`` (symmetric positive definite), iteration ``k`` is

.. math::

    \alpha_k = \frac{\langle r_k, z_k\rangle}{\langle p_k, A p_k\rangle},\quad
    x_{k+1} = x_k + \alpha_k p_k,\quad r_{k+1} = r_k - \alpha_k A p_k,\quad
    z_{k+1} = M r_{k+1},\quad
    \beta_k = \frac{\langle r_{k+1}, z_{k+1}\rangle}{\langle r_k, z_k\rangle},\quad
    p_{k+1} = z_{k+1} + \beta_k p_k ,

stopping a sample when ``‖r_k‖ ≤ tol · ‖b‖`` (``‖r_k‖ ≤ tol`` when ``b = 0``).
"""
from __future__ import annotations

from typing import Callable, NamedTuple, Optional

import torch

from .._checks import check_same_shape
from ..errors import DepthSRError, ShapeError

__all__ = ["CGResult", "conjugate_gradient"]

Operator = Callable[[torch.Tensor], torch.Tensor]


class CGResult(NamedTuple):
    """Result of a (batched) CG solve.

    Attributes:
        x: the solution, shape of ``b``.
        iterations: ``(B,)`` int64, CG iterations each sample took.
        residual: ``(B,)`` relative residual ``‖b − A x‖ / ‖b‖`` (recursively updated; absolute when
            ``b = 0``) at exit, in the dtype of ``b``.
        history: ``(n_iter + 1,)`` maximum over the batch of the relative residual before the first
            and after every iteration, or ``None`` where not recorded.
    """

    x: torch.Tensor
    iterations: torch.Tensor
    residual: torch.Tensor
    history: Optional[torch.Tensor] = None


def _bdot(u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    return (u * v).flatten(1).sum(dim=1)  # (B,)


def _bview(t: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    return t.view((-1,) + (1,) * (like.ndim - 1))  # (B, 1, 1, 1)


def _check_inputs(b: torch.Tensor, x0: torch.Tensor | None, tol: float, max_iter: int) -> None:
    if not isinstance(b, torch.Tensor):
        raise DepthSRError(f"b must be a torch.Tensor; got {type(b).__name__}.")
    if b.ndim < 1:
        raise ShapeError("b must have a leading batch dimension, e.g. (B,C,H,W); got a 0-d tensor.", actual=(),
                         expected="(B, ...), e.g. (B,C,H,W)")
    if not b.is_floating_point():
        raise DepthSRError(f"b must be a floating tensor (float32/float64); got {b.dtype}.")
    if x0 is not None:
        if not isinstance(x0, torch.Tensor):
            raise DepthSRError(f"x0 must be a torch.Tensor or None; got {type(x0).__name__}.")
        check_same_shape(x0, b, "x0", "b", "Pass x0=None for a zero start.")
    if isinstance(max_iter, bool) or not isinstance(max_iter, int) or max_iter < 0:
        raise DepthSRError(f"max_iter must be an int >= 0; got {max_iter!r}.")
    if not (float(tol) >= 0):
        raise DepthSRError(f"tol must be a float >= 0; got {tol!r}.")


def _apply(fn: Operator, v: torch.Tensor, name: str) -> torch.Tensor:
    out = fn(v)
    if not isinstance(out, torch.Tensor) or out.shape != v.shape:
        got = tuple(out.shape) if isinstance(out, torch.Tensor) else type(out).__name__
        raise ShapeError(f"{name} must map a tensor of shape {tuple(v.shape)} to the same shape; got {got}.",
                         actual=got if isinstance(got, tuple) else None, expected=str(tuple(v.shape)))
    return out


def conjugate_gradient(
    apply_A: Operator,
    b: torch.Tensor,
    x0: torch.Tensor | None = None,
    precond: Operator | None = None,
    tol: float = 1e-5,
    max_iter: int = 100,
    *,
    early_exit: bool = True,
) -> CGResult:
    r"""Batched preconditioned conjugate gradients for ``A x = b`` with ``A`` symmetric positive definite.

    Every sample ``b[i]`` is its own system (``apply_A`` must act sample-wise); dot products run over
    all non-batch dims. The loop stops when every sample has converged or after ``max_iter``
    iterations; converged samples are frozen (``x``, ``iterations`` and ``residual`` stop changing).
    A sample whose curvature ``⟨p, A p⟩`` is not positive (``A`` not SPD, or exact convergence) is
    also frozen; its ``residual`` then tells whether it converged.

    The loop is plain tensor code: under autograd it is differentiable (unrolled backpropagation);
    see :func:`torch_depth_sr.solvers.implicit.cg_solve` for the memory-flat implicit backward.
    With ``early_exit`` (the default) each iteration synchronises once with the device (the all-converged
    test); with ``early_exit=False`` exactly ``max_iter`` iterations run and nothing is read back to the host.
    Converged samples are frozen either way, so both give the same result; only the work differs.

    Args:
        apply_A: function ``v ↦ A v`` on tensors of the shape of ``b``.
        b: right-hand side, ``(B, ...)``, usually ``(B, C, H, W)``, float32 or float64.
        x0: warm start of the shape of ``b`` (default zeros).
        precond: function ``r ↦ M r`` with ``M ≈ A⁻¹`` SPD (e.g.
            :class:`~torch_depth_sr.solvers.dct.NeumannPreconditioner`); ``None`` for plain CG.
        tol: relative tolerance on ``‖b − A x‖ / ‖b‖`` per sample. In float32 values below about
            ``1e-6`` are not reachable and the solve runs to ``max_iter``.
        max_iter: maximum number of iterations (``0`` returns ``x0``).
        early_exit: stop once every sample has converged (a host synchronisation per iteration); False runs
            ``max_iter`` iterations, for a fixed amount of work and a forward the host never waits on.

    Returns:
        :class:`CGResult` ``(x, iterations (B,), residual (B,), history)``.

    Examples:
        >>> from torch_depth_sr.operators import laplacian
        >>> b = torch.randn(2, 1, 8, 8, dtype=torch.float64)
        >>> res = conjugate_gradient(lambda v: v + laplacian(v), b, tol=1e-10, max_iter=200)
        >>> bool(torch.allclose(res.x + laplacian(res.x), b, atol=1e-8))
        True
        >>> res.iterations.shape, bool((res.residual <= 1e-10).all())
        (torch.Size([2]), True)
    """
    _check_inputs(b, x0, tol, max_iter)
    if not isinstance(early_exit, bool):
        raise DepthSRError(f"early_exit must be True or False; got {early_exit!r}.")
    batch = b.shape[0]
    b_norm = torch.linalg.vector_norm(b.flatten(1), dim=1)  # (B,)
    b_norm_safe = torch.where(b_norm > 0, b_norm, torch.ones_like(b_norm))

    if x0 is None:
        x = torch.zeros_like(b)
        r = b
    else:
        x = x0
        r = b - _apply(apply_A, x, "apply_A")
    rel = torch.linalg.vector_norm(r.flatten(1), dim=1) / b_norm_safe  # (B,)
    done = rel <= tol  # (B,) bool
    iterations = torch.zeros(batch, dtype=torch.long, device=b.device)
    history = [rel.detach().max() if batch else rel.new_zeros(())]

    if max_iter > 0 and (not early_exit or not bool(done.all())):
        z = r if precond is None else _apply(precond, r, "precond")
        p = z
        rz = _bdot(r, z)  # (B,)
        first = True
        for it in range(max_iter):
            Ap = _apply(apply_A, p, "apply_A") if first else apply_A(p)
            first = False
            pAp = _bdot(p, Ap)  # (B,)
            active = ~done & (pAp > 0)  # (B,)
            done = done | ~active  # non-positive curvature freezes the sample
            alpha = torch.where(active, rz / torch.where(active, pAp, torch.ones_like(pAp)), torch.zeros_like(pAp))
            alpha_b = _bview(alpha, b)
            x = x + alpha_b * p
            r = r - alpha_b * Ap
            new_rel = torch.linalg.vector_norm(r.flatten(1), dim=1) / b_norm_safe
            rel = torch.where(active, new_rel, rel)
            iterations = iterations + active.long()
            done = done | (rel <= tol)
            history.append(rel.detach().max())
            if (early_exit and bool(done.all())) or it == max_iter - 1:
                break  # the last iteration: the next direction would never be used (x is final)
            z = r if precond is None else precond(r)
            rz_new = _bdot(r, z)
            keep = ~done & (rz != 0)
            beta = torch.where(keep, rz_new / torch.where(keep, rz, torch.ones_like(rz)), torch.zeros_like(rz))
            p = z + _bview(beta, b) * p
            rz = rz_new
    return CGResult(x=x, iterations=iterations, residual=rel, history=torch.stack(history))
