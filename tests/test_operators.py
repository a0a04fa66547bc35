"""Tests of torch_depth_sr.operators: D, Dᵀ, DᵀD (Neumann) and area downsampling K, Kᵀ."""
from __future__ import annotations

import pytest
import torch

from torch_depth_sr.errors import DepthSRError, ShapeError
from torch_depth_sr.operators import (
    AreaDownsample,
    BicubicDownsample,
    Degradation,
    Gradient,
    Identity,
    area_downsample,
    area_downsample_adjoint,
    degradation_operator,
    dot_test,
    grad,
    grad_adjoint,
    laplacian,
)


def neumann_laplacian_matrix(h: int, w: int) -> torch.Tensor:
    """Hand-built 5-point Neumann Laplacian: degree on the diagonal, −1 per in-image neighbour."""
    n = h * w
    mat = torch.zeros(n, n, dtype=torch.float64)
    for i in range(h):
        for j in range(w):
            p = i * w + j
            for di, dj in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                ii, jj = i + di, j + dj
                if 0 <= ii < h and 0 <= jj < w:
                    mat[p, p] += 1.0
                    mat[p, ii * w + jj] -= 1.0
    return mat


def operator_matrix(fn, h: int, w: int) -> torch.Tensor:
    """Dense matrix of a (1,1,h,w) -> (1,1,h,w) linear map, column k = fn(e_k)."""
    basis = torch.eye(h * w, dtype=torch.float64).view(h * w, 1, h, w)  # (N, 1, H, W)
    return fn(basis).reshape(h * w, h * w).T


class TestGrad:
    def test_smoke_values(self):
        x = torch.tensor([[[[0.0, 1.0, 3.0], [2.0, 2.0, 2.0]]]])
        g = grad(x)
        assert g.shape == (1, 2, 2, 3)
        torch.testing.assert_close(g[0, 0], torch.tensor([[1.0, 2.0, 0.0], [0.0, 0.0, 0.0]]))
        torch.testing.assert_close(g[0, 1], torch.tensor([[2.0, 1.0, -1.0], [0.0, 0.0, 0.0]]))

    def test_cardinality_multichannel(self):
        x = torch.randn(3, 2, 5, 7)
        g = grad(x)
        assert g.shape == (3, 4, 5, 7)
        torch.testing.assert_close(g[:, 1], grad(x[:, 1:2])[:, 0])  # horizontal of channel 1
        torch.testing.assert_close(g[:, 3], grad(x[:, 1:2])[:, 1])  # vertical of channel 1
        assert grad_adjoint(g).shape == x.shape

    def test_neumann_boundary_zero(self):
        g = grad(torch.randn(2, 1, 4, 5))
        assert (g[:, 0, :, -1] == 0).all() and (g[:, 1, -1, :] == 0).all()

    def test_constant_has_zero_gradient(self):
        assert (grad(torch.full((1, 1, 4, 4), 3.0)) == 0).all()

    def test_exception(self):
        with pytest.raises(ShapeError, match=r"\(B,C,H,W\).*\(4, 4\)"):
            grad(torch.zeros(4, 4))
        with pytest.raises(ShapeError, match="even number of channels"):
            grad_adjoint(torch.zeros(1, 3, 4, 4))
        with pytest.raises(DepthSRError, match="floating"):
            grad(torch.zeros(1, 1, 4, 4, dtype=torch.long))

    def test_noncontiguous(self):
        x = torch.randn(2, 1, 6, 5).transpose(-1, -2)
        assert not x.is_contiguous()
        torch.testing.assert_close(grad(x), grad(x.contiguous()))
        torch.testing.assert_close(laplacian(x), laplacian(x.contiguous()))

    def test_no_inplace_dtype_kept(self):
        for dtype in (torch.float32, torch.float64):
            x = torch.randn(2, 1, 5, 5, dtype=dtype)
            x_copy = x.clone()
            out = laplacian(x)
            assert out.dtype == dtype and out.device == x.device
            torch.testing.assert_close(x, x_copy, rtol=0, atol=0)

    def test_single_pixel_dims(self):
        x = torch.randn(1, 1, 1, 5, dtype=torch.float64)
        assert (grad(x)[:, 1] == 0).all()
        assert dot_test(Gradient(), (1, 1, 1, 5), (1, 2, 1, 5)) < 1e-12

    @pytest.mark.parametrize("hw", [(5, 6), (1, 4), (4, 1), (3, 3)])
    def test_laplacian_equals_hand_built_matrix(self, hw):
        h, w = hw
        dense = operator_matrix(laplacian, h, w)
        torch.testing.assert_close(dense, neumann_laplacian_matrix(h, w), rtol=0, atol=1e-14)

    def test_laplacian_psd_and_nullspace(self):
        dense = operator_matrix(laplacian, 4, 5)
        torch.testing.assert_close(dense, dense.T)
        eig = torch.linalg.eigvalsh(dense)
        assert eig.min() > -1e-12
        assert (eig.abs() < 1e-10).sum() == 1  # constants only

    def test_gradcheck(self):
        x = torch.randn(2, 1, 4, 5, dtype=torch.float64, requires_grad=True)
        assert torch.autograd.gradcheck(grad, (x,))
        p = torch.randn(2, 2, 4, 5, dtype=torch.float64, requires_grad=True)
        assert torch.autograd.gradcheck(grad_adjoint, (p,))


class TestAreaDownsample:
    @pytest.mark.parametrize("s", [2, 3, 4])
    def test_matches_block_mean_loop(self, s):
        x = torch.randn(2, 3, 4 * s, 3 * s, dtype=torch.float64)
        out = area_downsample(x, s)
        assert out.shape == (2, 3, 4, 3)
        ref = torch.empty_like(out)
        for i in range(4):
            for j in range(3):
                ref[..., i, j] = x[..., i * s : (i + 1) * s, j * s : (j + 1) * s].mean(dim=(-1, -2))
        torch.testing.assert_close(out, ref)

    @pytest.mark.parametrize("s", [1, 2, 3, 4])
    def test_adjoint_properties(self, s):
        v = torch.randn(2, 1, 3, 5, dtype=torch.float64)
        up = area_downsample_adjoint(v, s)
        assert up.shape == (2, 1, 3 * s, 5 * s)
        torch.testing.assert_close(area_downsample(up, s), v / s**2)  # K Kᵀ = I / s²

    def test_exception(self):
        with pytest.raises(ShapeError, match=r"divisible by s=3.*\(1, 1, 7, 9\)"):
            area_downsample(torch.zeros(1, 1, 7, 9), 3)
        with pytest.raises(DepthSRError, match="int >= 1"):
            AreaDownsample(0)
        with pytest.raises(DepthSRError, match="int >= 1"):
            area_downsample(torch.zeros(1, 1, 4, 4), 2.0)

    def test_noncontiguous(self):
        x = torch.randn(1, 2, 6, 8).permute(0, 1, 3, 2)
        torch.testing.assert_close(area_downsample(x, 2), area_downsample(x.contiguous(), 2))

    def test_module_equals_functional(self):
        x = torch.randn(1, 1, 6, 6)
        K = AreaDownsample(3)
        torch.testing.assert_close(K(x), area_downsample(x, 3))
        torch.testing.assert_close(K.normal(x), area_downsample_adjoint(area_downsample(x, 3), 3))
        assert "s=3" in repr(K)


OPERATORS = [
    pytest.param(Gradient(), (2, 1, 6, 7), (2, 2, 6, 7), id="gradient"),
    pytest.param(Gradient(), (2, 3, 5, 4), (2, 6, 5, 4), id="gradient-3ch"),
    pytest.param(Identity(), (2, 1, 6, 7), (2, 1, 6, 7), id="identity"),
    pytest.param(AreaDownsample(1), (2, 1, 6, 7), (2, 1, 6, 7), id="area-s1"),
    pytest.param(AreaDownsample(2), (2, 1, 8, 6), (2, 1, 4, 3), id="area-s2"),
    pytest.param(AreaDownsample(3), (2, 2, 9, 12), (2, 2, 3, 4), id="area-s3"),
    pytest.param(AreaDownsample(4), (1, 1, 16, 8), (1, 1, 4, 2), id="area-s4"),
    pytest.param(BicubicDownsample(2), (2, 1, 12, 10), (2, 1, 6, 5), id="bicubic-s2"),
]


@pytest.mark.parametrize("op, x_shape, y_shape", OPERATORS)
def test_dot_test_every_operator(op, x_shape, y_shape):
    gen = torch.Generator().manual_seed(0)
    for _ in range(3):
        assert dot_test(op, x_shape, y_shape, torch.float64, generator=gen) < 1e-13


@pytest.mark.parametrize("op, x_shape, y_shape", OPERATORS)
def test_normal_is_adjoint_of_forward(op, x_shape, y_shape):
    x = torch.randn(x_shape, dtype=torch.float64)
    torch.testing.assert_close(op.normal(x), op.adjoint(op.forward(x)))


def test_dot_test_float32():
    assert dot_test(Gradient(), (1, 1, 16, 16), (1, 2, 16, 16), torch.float32) < 1e-5


def test_dot_test_shape_error():
    with pytest.raises(ShapeError, match="not to y_shape"):
        dot_test(AreaDownsample(2), (1, 1, 4, 4), (1, 1, 4, 4))


def test_bicubic_downsample_is_torch_antialiased_bicubic_and_its_adjoint_is_exact():
    from torch_depth_sr.operators import BicubicDownsample, dot_test

    g = torch.Generator().manual_seed(0)
    for s, (h, w) in ((2, (12, 10)), (4, (40, 48))):
        x = torch.rand(2, 1, h, w, generator=g, dtype=torch.float64)
        K = BicubicDownsample(s)
        ref = torch.nn.functional.interpolate(x, size=(h // s, w // s), mode="bicubic", antialias=True,
                                              align_corners=False)
        torch.testing.assert_close(K(x), ref)
        assert dot_test(K, (2, 1, h, w), (2, 1, h // s, w // s)) < 1e-12


def test_model_with_bicubic_degradation_upsamples():
    from torch_depth_sr import DepthRestorer
    from torch_depth_sr.datasets.synthetic import make_scene

    s = make_scene(48, 64, seed=0)
    lr = torch.nn.functional.interpolate(s["gt"][None], size=(12, 16), mode="bicubic", antialias=True,
                                         align_corners=False)
    out = DepthRestorer(degradation="bicubic", num_layers=2)(lr, s["rgb"][None])
    assert out.shape == (1, 1, 48, 64) and torch.isfinite(out).all()


class TestDegradation:
    """The task as an operator: what the model builds and what the layers read of it."""

    @pytest.mark.parametrize("kind, s, cls, identity", [
        ("area", 1, Identity, True), ("bicubic", 1, Identity, True),
        ("area", 2, AreaDownsample, False), ("area", 3, AreaDownsample, False),
        ("bicubic", 4, BicubicDownsample, False),
    ])
    def test_factory_builds_the_operator_of_the_task(self, kind, s, cls, identity):
        K = degradation_operator(kind, s)
        assert type(K) is cls and isinstance(K, Degradation)
        assert K.scale == s and K.is_identity is identity

    def test_factory_refuses_unknown_kind_and_bad_factor(self):
        with pytest.raises(DepthSRError, match="allowed are"):
            degradation_operator("nearest", 2)
        with pytest.raises(DepthSRError, match="int >= 1"):
            degradation_operator("area", 0)

    @pytest.mark.parametrize("K", [AreaDownsample(2), AreaDownsample(3), BicubicDownsample(2), BicubicDownsample(4)],
                             ids=repr)
    def test_normal_maps_a_constant_to_one_over_s_squared_in_the_interior(self, K):
        # what the model's preconditioner assumes of KᵀK (exact for area; away from the border for bicubic)
        s = K.scale
        x = torch.ones(1, 1, 12 * s, 12 * s, dtype=torch.float64)
        inner = K.normal(x)[..., 4 * s:-4 * s, 4 * s:-4 * s]
        torch.testing.assert_close(inner, torch.full_like(inner, 1 / s ** 2))

    @pytest.mark.parametrize("s", [2, 3, 5, 16])
    def test_area_adjoint_replicates_each_pixel(self, s):
        v = torch.randn(2, 1, 7, 9, dtype=torch.float64)
        ref = v.repeat_interleave(s, dim=-2).repeat_interleave(s, dim=-1) / s ** 2
        assert torch.equal(area_downsample_adjoint(v, s), ref)
