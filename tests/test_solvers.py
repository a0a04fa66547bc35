"""Tests of torch_depth_sr.solvers: batched PCG, DCT Neumann solver/preconditioner, implicit backward."""
from __future__ import annotations

import math
import pickle

import pytest
import torch

from torch_depth_sr.errors import DepthSRError, ShapeError
from torch_depth_sr.operators import laplacian
from torch_depth_sr.solvers import (
    CGResult,
    NeumannPreconditioner,
    cg_solve,
    conjugate_gradient,
    dct2,
    dct_matrix,
    idct2,
    neumann_eigenvalues,
    solve_neumann,
)

F64 = torch.float64


def dense_of(apply_fn, shape) -> torch.Tensor:
    """Dense (B, N, N) matrices of a sample-wise linear map on tensors of shape (B, C, H, W)."""
    b = shape[0]
    n = math.prod(shape[1:])
    basis = torch.eye(n, dtype=F64).view(n, 1, *shape[1:]).expand(n, b, *shape[1:])  # (N, B, C, H, W)
    cols = torch.stack([apply_fn(basis[k].clone()).reshape(b, n) for k in range(n)], dim=-1)  # (B, N, N)
    return cols


def masked_system(shape, c, p_keep=0.7, seed=0, dtype=F64):
    gen = torch.Generator().manual_seed(seed)
    q = (torch.rand(shape, generator=gen, dtype=F64) < p_keep).to(dtype)
    b = torch.randn(shape, generator=gen, dtype=F64).to(dtype)
    c_b = c.view(-1, 1, 1, 1) if isinstance(c, torch.Tensor) else c
    return q, b, (lambda v: q * v + c_b * laplacian(v))


# ---------------------------------------------------------------------------------------------
# DCT
# ---------------------------------------------------------------------------------------------
class TestDCT:
    @pytest.mark.parametrize("n", [1, 2, 5, 8])
    def test_matrix_orthonormal_and_formula(self, n):
        c = dct_matrix(n)
        torch.testing.assert_close(c @ c.T, torch.eye(n, dtype=F64))
        k, i = 1 % n, 0
        expected = math.sqrt(2 / n) * math.cos(math.pi * (2 * i + 1) * k / (2 * n)) if k else math.sqrt(1 / n)
        assert abs(float(c[k, i]) - expected) < 1e-12

    def test_roundtrip_and_parseval(self):
        x = torch.randn(2, 3, 7, 5, dtype=F64)
        X = dct2(x)
        torch.testing.assert_close(idct2(X), x)
        torch.testing.assert_close(X.norm(), x.norm())

    def test_diagonalises_neumann_laplacian(self):
        x = torch.randn(2, 1, 6, 9, dtype=F64)
        torch.testing.assert_close(dct2(laplacian(x)), neumann_eigenvalues(6, 9) * dct2(x))

    def test_dtype_device_cached(self):
        x = torch.randn(1, 1, 4, 4)
        assert dct2(x).dtype == torch.float32
        assert dct_matrix(4, torch.float32) is dct_matrix(4, torch.float32)

    def test_noncontiguous(self):
        x = torch.randn(2, 1, 5, 6, dtype=F64).transpose(-1, -2)
        torch.testing.assert_close(dct2(x), dct2(x.contiguous()))

    def test_exception(self):
        with pytest.raises(ShapeError, match="at least 2 dims"):
            dct2(torch.zeros(4))
        with pytest.raises(DepthSRError, match="int >= 1"):
            dct_matrix(0)


class TestSolveNeumann:
    @pytest.mark.parametrize(
        "a, c",
        [(0.5, 2.0), (torch.tensor([0.1, 1.0, 3.0]), 1.0), (1.0, torch.tensor([0.5, 1.0, 4.0]))],
        ids=["floats", "a-per-sample", "c-per-sample"],
    )
    def test_against_dense_solve(self, a, c):
        shape = (3, 1, 5, 6)
        b = torch.randn(shape, dtype=F64)
        a_b = a.view(-1, 1, 1, 1) if isinstance(a, torch.Tensor) else a
        c_b = c.view(-1, 1, 1, 1) if isinstance(c, torch.Tensor) else c
        mats = dense_of(lambda v: a_b * v + c_b * laplacian(v), shape)  # (3, 30, 30)
        ref = torch.linalg.solve(mats, b.reshape(3, -1, 1)).reshape(shape)
        torch.testing.assert_close(solve_neumann(b, a, c), ref, rtol=1e-10, atol=1e-10)

    def test_multichannel(self):
        b = torch.randn(2, 3, 4, 5, dtype=F64)
        x = solve_neumann(b, 0.7, 1.3)
        torch.testing.assert_close(0.7 * x + 1.3 * laplacian(x), b)

    def test_a_zero_gives_zero_mean_solution(self):
        b = torch.randn(2, 1, 6, 5, dtype=F64)
        b0 = b - b.mean(dim=(-1, -2), keepdim=True)
        x = solve_neumann(b0, 0.0, 2.0)
        torch.testing.assert_close(2.0 * laplacian(x), b0)
        assert x.mean(dim=(-1, -2)).abs().max() < 1e-12
        # b with a mean: least-squares solution, mean of b dropped
        torch.testing.assert_close(solve_neumann(b, 0.0, 2.0), x)
        # keep_mean passes the mean through
        xk = solve_neumann(b, 0.0, 2.0, keep_mean=True)
        torch.testing.assert_close(xk.mean(dim=(-1, -2)), b.mean(dim=(-1, -2)))

    def test_a_zero_in_one_sample(self):
        b = torch.randn(2, 1, 4, 4, dtype=F64)
        b = b - b.mean(dim=(-1, -2), keepdim=True)
        x = solve_neumann(b, torch.tensor([0.0, 1.0]), 1.0)
        torch.testing.assert_close(x[0:1], solve_neumann(b[0:1], 0.0, 1.0))
        torch.testing.assert_close(x[1:2], solve_neumann(b[1:2], 1.0, 1.0))

    def test_gradcheck(self):
        b = torch.randn(2, 1, 4, 5, dtype=F64, requires_grad=True)
        a = torch.tensor([0.3, 1.2], dtype=F64, requires_grad=True)
        assert torch.autograd.gradcheck(lambda b_, a_: solve_neumann(b_, a_, 0.8), (b, a))

    def test_exception(self):
        b = torch.zeros(2, 1, 4, 4)
        with pytest.raises(DepthSRError, match="c must be a finite float > 0"):
            solve_neumann(b, 1.0, 0.0)
        with pytest.raises(DepthSRError, match="a must be a finite float >= 0"):
            solve_neumann(b, -1.0, 1.0)
        with pytest.raises(ShapeError, match=r"per-sample \(B,\) tensor with B=2.*\(3,\)"):
            solve_neumann(b, torch.ones(3), 1.0)
        with pytest.raises(ShapeError, match=r"\(B,C,H,W\)"):
            solve_neumann(torch.zeros(4, 4), 1.0, 1.0)


# ---------------------------------------------------------------------------------------------
# CG
# ---------------------------------------------------------------------------------------------
class TestConjugateGradient:
    def test_against_dense_with_different_iteration_counts(self):
        shape = (3, 1, 5, 6)
        c = torch.tensor([0.05, 1.0, 20.0], dtype=F64)  # very different conditioning
        q, b, apply_A = masked_system(shape, c)
        res = conjugate_gradient(apply_A, b, tol=1e-12, max_iter=500)
        assert isinstance(res, CGResult)
        ref = torch.linalg.solve(dense_of(apply_A, shape), b.reshape(3, -1, 1)).reshape(shape)
        torch.testing.assert_close(res.x, ref, rtol=1e-9, atol=1e-9)
        assert res.iterations.dtype == torch.long and res.iterations.shape == (3,)
        assert len(set(res.iterations.tolist())) > 1, res.iterations
        assert (res.residual <= 1e-12).all()
        # each sample solved alone takes the same number of iterations: converged samples are frozen
        for i in range(3):
            qi, ci = q[i : i + 1], c[i]
            alone = conjugate_gradient(lambda v: qi * v + ci * laplacian(v), b[i : i + 1], tol=1e-12, max_iter=500)
            assert int(alone.iterations) == int(res.iterations[i])
            torch.testing.assert_close(alone.x, res.x[i : i + 1], rtol=1e-12, atol=1e-12)

    def test_history(self):
        q, b, apply_A = masked_system((2, 1, 6, 6), 1.0)
        res = conjugate_gradient(apply_A, b, tol=1e-8, max_iter=200)
        assert res.history.shape == (int(res.iterations.max()) + 1,)
        assert res.history[0] == pytest.approx(1.0)
        assert float(res.history[-1]) == pytest.approx(float(res.residual.max()))

    def test_result_pickles(self):
        q, b, apply_A = masked_system((2, 1, 4, 4), 1.0)
        res = pickle.loads(pickle.dumps(conjugate_gradient(apply_A, b, tol=1e-8)))
        assert isinstance(res, CGResult) and res.history is not None

    def test_float32(self):
        q, b, apply_A = masked_system((2, 1, 16, 16), 1.0, dtype=torch.float32)
        res = conjugate_gradient(apply_A, b, tol=1e-5, max_iter=300)
        assert res.x.dtype == torch.float32 and (res.residual <= 1e-5).all()
        true_rel = (apply_A(res.x) - b).flatten(1).norm(dim=1) / b.flatten(1).norm(dim=1)
        assert (true_rel < 1e-4).all()

    def test_warm_start(self):
        q, b, apply_A = masked_system((2, 1, 8, 8), 1.0)
        exact = conjugate_gradient(apply_A, b, tol=1e-13, max_iter=500).x
        res = conjugate_gradient(apply_A, b, x0=exact, tol=1e-8, max_iter=500)
        assert (res.iterations == 0).all()
        near = conjugate_gradient(apply_A, b, x0=exact + 1e-6 * torch.randn_like(exact), tol=1e-8)
        cold = conjugate_gradient(apply_A, b, tol=1e-8)
        assert (near.iterations < cold.iterations).all()
        torch.testing.assert_close(near.x, exact, atol=1e-7, rtol=0)

    def test_zero_rhs(self):
        q, b, apply_A = masked_system((2, 1, 5, 5), 1.0)
        b = b.clone()
        b[0] = 0
        res = conjugate_gradient(apply_A, b, tol=1e-10, max_iter=200)
        assert torch.isfinite(res.x).all() and (res.x[0] == 0).all()
        assert int(res.iterations[0]) == 0 and int(res.iterations[1]) > 0
        assert (res.residual <= 1e-10).all()

    def test_max_iter_zero_and_cap(self):
        q, b, apply_A = masked_system((2, 1, 8, 8), 0.5)
        res = conjugate_gradient(apply_A, b, max_iter=0)
        assert (res.x == 0).all() and (res.iterations == 0).all()
        res = conjugate_gradient(apply_A, b, tol=1e-14, max_iter=3)
        assert (res.iterations == 3).all() and (res.residual > 1e-14).all()

    def test_inputs_not_modified(self):
        q, b, apply_A = masked_system((2, 1, 6, 6), 1.0)
        x0 = torch.randn_like(b)
        b_copy, x0_copy = b.clone(), x0.clone()
        conjugate_gradient(apply_A, b, x0=x0, tol=1e-8)
        assert torch.equal(b, b_copy) and torch.equal(x0, x0_copy)

    def test_exception(self):
        b = torch.zeros(2, 1, 4, 4)
        with pytest.raises(ShapeError, match=r"x0 must have the shape of b \(2, 1, 4, 4\); got \(2, 1, 4, 5\)"):
            conjugate_gradient(lambda v: v, b, x0=torch.zeros(2, 1, 4, 5))
        with pytest.raises(ShapeError, match="apply_A must map a tensor of shape"):
            conjugate_gradient(lambda v: v[..., :2], torch.ones(2, 1, 4, 4))
        with pytest.raises(DepthSRError, match="max_iter must be an int >= 0"):
            conjugate_gradient(lambda v: v, b, max_iter=-1)
        with pytest.raises(DepthSRError, match="floating"):
            conjugate_gradient(lambda v: v, torch.zeros(2, 3, dtype=torch.long))

    def test_unrolled_gradcheck(self):
        q, b, apply_A = masked_system((2, 1, 4, 4), 1.0)
        b = b.requires_grad_()
        assert torch.autograd.gradcheck(lambda b_: conjugate_gradient(apply_A, b_, tol=1e-13, max_iter=200).x, (b,))


class TestNeumannPreconditioner:
    def test_exact_when_system_is_diagonalisable(self):
        b = torch.randn(2, 1, 16, 16, dtype=F64)
        apply_A = lambda v: 0.7 * v + 2.0 * laplacian(v)  # noqa: E731
        res = conjugate_gradient(apply_A, b, precond=NeumannPreconditioner(0.7, 2.0), tol=1e-10)
        assert (res.iterations == 1).all()

    @pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
    def test_far_fewer_iterations_on_masked_system(self, dtype):
        shape, c = (2, 1, 64, 64), 10.0
        q, b, apply_A = masked_system(shape, c, p_keep=0.7, dtype=dtype)
        tol = 1e-8 if dtype == torch.float64 else 1e-5
        plain = conjugate_gradient(apply_A, b, tol=tol, max_iter=2000)
        pcg = conjugate_gradient(apply_A, b, precond=NeumannPreconditioner.from_diagonal(q, c), tol=tol, max_iter=2000)
        msg = f"iterations without preconditioner {plain.iterations.tolist()}, with DCT {pcg.iterations.tolist()}"
        print(msg)
        assert (pcg.residual <= tol).all() and (plain.residual <= tol).all(), msg
        assert (4 * pcg.iterations < plain.iterations).all(), msg
        torch.testing.assert_close(pcg.x, plain.x, rtol=0, atol=1e-4 if dtype == torch.float32 else 1e-6)

    def test_a_zero_stays_positive_definite(self):
        q, b, apply_A = masked_system((1, 1, 16, 16), 1.0)
        res = conjugate_gradient(apply_A, b, precond=NeumannPreconditioner(0.0, 1.0), tol=1e-10, max_iter=500)
        assert (res.residual <= 1e-10).all()


# ---------------------------------------------------------------------------------------------
# Implicit differentiation
# ---------------------------------------------------------------------------------------------
class TestImplicitCG:
    TOL = 1e-12

    def _solve(self, q, b, mu, implicit=True, precond=None):
        mu_b = mu.view(-1, 1, 1, 1) if mu.ndim == 1 else mu
        return cg_solve(
            lambda v: q * v + mu_b * laplacian(v),
            b,
            precond=precond,
            tol=self.TOL,
            max_iter=500,
            implicit=implicit,
            params=(mu,),
        )

    @pytest.mark.parametrize("mu_shape", [(), (2,)], ids=["scalar-mu", "per-sample-mu"])
    def test_gradcheck_b_and_mu(self, mu_shape):
        q, b, _ = masked_system((2, 1, 4, 5), 1.0)
        b = b.requires_grad_()
        mu = (0.5 + torch.rand(mu_shape, dtype=F64)).requires_grad_()
        assert torch.autograd.gradcheck(lambda b_, mu_: self._solve(q, b_, mu_).x, (b, mu), atol=1e-6)

    def test_gradcheck_with_preconditioner_and_nonleaf_param(self):
        q, b, _ = masked_system((2, 1, 4, 4), 1.0, seed=3)
        raw = torch.tensor(0.2, dtype=F64, requires_grad=True)
        b = b.requires_grad_()

        def f(b_, raw_):
            mu = torch.nn.functional.softplus(raw_)  # non-leaf parameter used by apply_A
            return self._solve(q, b_, mu, precond=NeumannPreconditioner.from_diagonal(q, 0.7)).x

        assert torch.autograd.gradcheck(f, (b, raw), atol=1e-6)

    def test_implicit_matches_unrolled(self):
        q, b, _ = masked_system((3, 1, 6, 6), 1.0, seed=1)
        grads = []
        for implicit in (True, False):
            bb = b.clone().requires_grad_()
            mu = torch.tensor([0.3, 1.0, 3.0], dtype=F64, requires_grad=True)
            x = self._solve(q, bb, mu, implicit=implicit).x
            (x * torch.linspace(-1, 1, x.numel(), dtype=F64).view_as(x)).sum().backward()
            grads.append((bb.grad, mu.grad))
        torch.testing.assert_close(grads[0][0], grads[1][0], rtol=1e-8, atol=1e-10)
        torch.testing.assert_close(grads[0][1], grads[1][1], rtol=1e-8, atol=1e-10)

    def test_outputs(self):
        q, b, _ = masked_system((2, 1, 5, 5), 1.0)
        b = b.requires_grad_()
        mu = torch.tensor(1.0, dtype=F64, requires_grad=True)
        res = self._solve(q, b, mu)
        assert res.x.requires_grad and not res.residual.requires_grad
        assert res.iterations.dtype == torch.long and (res.residual <= self.TOL).all()
        with torch.no_grad():
            plain = conjugate_gradient(lambda v: q * v + mu * laplacian(v), b, tol=self.TOL, max_iter=500)
        torch.testing.assert_close(res.x.detach(), plain.x)

    def test_warm_start_gets_no_gradient_and_nothing_tracked_without_grad(self):
        q, b, apply_A = masked_system((2, 1, 5, 5), 1.0)
        x0 = torch.randn_like(b, requires_grad=True)
        bb = b.clone().requires_grad_()
        cg_solve(apply_A, bb, x0=x0, tol=1e-10).x.sum().backward()
        assert x0.grad is None and bb.grad is not None
        res = cg_solve(apply_A, b, tol=1e-10)
        assert not res.x.requires_grad

    def test_exception(self):
        with pytest.raises(DepthSRError, match=r"params\[0\] must be a torch.Tensor"):
            cg_solve(lambda v: v, torch.ones(1, 1, 2, 2, requires_grad=True), params=(1.0,))
