"""Tests of torch_depth_sr.shrinkage: soft thresholds and the SoftThreshold module."""
from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F

from torch_depth_sr.errors import DepthSRError, ShapeError
from torch_depth_sr.shrinkage import SoftThreshold, group_soft_threshold, soft_threshold


def soft_ref(v, t):
    out = torch.zeros_like(v)
    out = torch.where(v > t, v - t, out)
    return torch.where(v < -t, v + t, out)


def gsoft_ref(v, t):
    n = torch.sqrt((v * v).sum(dim=1, keepdim=True))
    return torch.where(n > t, v * (1 - t / n.clamp_min(1e-300)), torch.zeros_like(v))


def _away_from_kinks(v: torch.Tensor, t: float, gap: float = 0.05) -> torch.Tensor:
    """Move entries with |v| close to t away from the kink (finite differences need smoothness)."""
    close = (v.abs() - t).abs() < gap
    return torch.where(close, v + 3 * gap * torch.sign(v), v)


class TestSoftThreshold:
    def test_smoke_values(self):
        v = torch.tensor([-3.0, -0.5, 0.0, 0.5, 2.0])
        torch.testing.assert_close(soft_threshold(v, 1.0), torch.tensor([-2.0, 0.0, 0.0, 0.0, 1.0]))
        torch.testing.assert_close(soft_threshold(v, 0.0), v)

    def test_matches_reference(self):
        v = torch.randn(3, 2, 5, 5)
        torch.testing.assert_close(soft_threshold(v, 0.3), soft_ref(v, 0.3))

    def test_per_sample_threshold(self):
        v = torch.randn(3, 2, 4, 4)
        t = torch.tensor([0.1, 0.5, 2.0])
        out = soft_threshold(v, t)
        for i in range(3):
            torch.testing.assert_close(out[i], soft_ref(v[i], float(t[i])))

    def test_broadcast_tensor_threshold(self):
        v = torch.randn(2, 2, 4, 4)
        t = torch.rand(1, 2, 1, 1)
        torch.testing.assert_close(soft_threshold(v, t), soft_ref(v, t))

    def test_exception(self):
        with pytest.raises(ShapeError, match=r"\(5,\).*\(3, 1, 4, 4\)"):
            soft_threshold(torch.zeros(3, 1, 4, 4), torch.ones(5))
        with pytest.raises(DepthSRError, match=">= 0"):
            soft_threshold(torch.zeros(3), -1.0)
        with pytest.raises(DepthSRError, match="float or a tensor"):
            soft_threshold(torch.zeros(3), "1")

    def test_noncontiguous(self):
        v = torch.randn(2, 1, 5, 6).transpose(-1, -2)
        torch.testing.assert_close(soft_threshold(v, 0.2), soft_threshold(v.contiguous(), 0.2))

    def test_dtype_kept_and_no_inplace(self):
        v = torch.randn(2, 1, 3, 3, dtype=torch.float64)
        v_copy = v.clone()
        out = soft_threshold(v, torch.tensor([0.1, 0.2]))  # float32 threshold, float64 input
        assert out.dtype == torch.float64
        torch.testing.assert_close(v, v_copy, rtol=0, atol=0)

    def test_gradcheck(self):
        t = torch.tensor([0.3, 0.6], dtype=torch.float64, requires_grad=True)
        v = _away_from_kinks(torch.randn(2, 1, 4, 4, dtype=torch.float64), 0.6)
        v = _away_from_kinks(v, 0.3).requires_grad_()
        assert torch.autograd.gradcheck(soft_threshold, (v, t))


class TestGroupSoftThreshold:
    def test_smoke_values(self):
        v = torch.tensor([3.0, 4.0]).view(1, 2, 1, 1)
        torch.testing.assert_close(group_soft_threshold(v, 2.5).flatten(), torch.tensor([1.5, 2.0]))
        assert (group_soft_threshold(v, 5.0) == 0).all()

    def test_matches_reference_and_per_sample(self):
        v = torch.randn(3, 2, 5, 5, dtype=torch.float64)
        t = torch.tensor([0.2, 0.8, 1.5], dtype=torch.float64)
        out = group_soft_threshold(v, t)
        for i in range(3):
            torch.testing.assert_close(out[i : i + 1], gsoft_ref(v[i : i + 1], float(t[i])))

    def test_zero_threshold_is_identity(self):
        v = torch.randn(2, 2, 3, 3)
        v[0, :, 0, 0] = 0
        torch.testing.assert_close(group_soft_threshold(v, 0.0), v)

    def test_finite_gradient_at_zero(self):
        v = torch.zeros(1, 2, 3, 3, requires_grad=True)
        t = torch.tensor(0.5, requires_grad=True)
        group_soft_threshold(v, t).sum().backward()
        assert torch.isfinite(v.grad).all() and torch.isfinite(t.grad).all()
        v = torch.zeros(1, 2, 3, 3, requires_grad=True)
        group_soft_threshold(v, 0.0).sum().backward()
        assert torch.isfinite(v.grad).all()

    def test_other_dim(self):
        v = torch.randn(2, 3, 4, 2)
        torch.testing.assert_close(
            group_soft_threshold(v, 0.4, dim=-1), gsoft_ref(v.movedim(-1, 1), 0.4).movedim(1, -1)
        )

    def test_exception(self):
        with pytest.raises(ShapeError, match="dim=4 is out of range"):
            group_soft_threshold(torch.zeros(1, 2, 3, 3), 0.1, dim=4)

    def test_gradcheck(self):
        v = torch.randn(2, 2, 3, 3, dtype=torch.float64)
        n = torch.sqrt((v * v).sum(1, keepdim=True))
        v = torch.where((n - 0.5).abs() < 0.05, v * 1.3, v).requires_grad_()
        t = torch.tensor(0.5, dtype=torch.float64, requires_grad=True)
        assert torch.autograd.gradcheck(group_soft_threshold, (v, t))


class TestSoftThresholdModule:
    def test_module_equals_functional(self):
        v = torch.randn(2, 2, 4, 4)
        torch.testing.assert_close(SoftThreshold(0.3)(v), soft_threshold(v, 0.3))
        torch.testing.assert_close(SoftThreshold(0.3, isotropic=True)(v), group_soft_threshold(v, 0.3))
        torch.testing.assert_close(SoftThreshold(0.3, learnable=True)(v), soft_threshold(v, 0.3))

    def test_learnable_parameters(self):
        st = SoftThreshold(0.2, learnable=True)
        names = [n for n, p in st.named_parameters() if p.requires_grad]
        assert names == ["raw"]
        torch.testing.assert_close(st.threshold, torch.tensor(0.2))
        with torch.no_grad():
            st.raw.fill_(-50.0)
        assert st.threshold > 0  # softplus keeps it positive
        fixed = SoftThreshold(0.2)
        assert list(fixed.parameters()) == [] and "_threshold" in fixed.state_dict()

    def test_gradient_reaches_raw(self):
        # d/dt Σ soft(v, t) = −Σ_{|v|>t} sign(v), and dt/draw = sigmoid(raw)
        st = SoftThreshold(0.2, learnable=True)
        st(torch.tensor([1.0, 2.0, -3.0, 0.1])).sum().backward()
        torch.testing.assert_close(st.raw.grad, -1.0 * torch.sigmoid(st.raw.detach()))

    def test_per_sample_threshold_and_scale(self):
        v = torch.randn(3, 1, 4, 4)
        t = torch.tensor([0.1, 0.5, 1.0])
        st = SoftThreshold(t, learnable=True)
        torch.testing.assert_close(st(v), soft_threshold(v, t))
        scale = torch.tensor([2.0, 1.0, 0.5])
        torch.testing.assert_close(st(v, scale=scale), soft_threshold(v, t * scale))
        torch.testing.assert_close(SoftThreshold(0.5)(v, scale=2.0), soft_threshold(v, 1.0))
        with pytest.raises(ShapeError, match="per-sample threshold of length 3"):
            st(torch.randn(2, 1, 4, 4))

    def test_dtype_and_to(self):
        st = SoftThreshold(0.3).to(torch.float64)
        v = torch.randn(2, 1, 3, 3, dtype=torch.float64)
        assert st(v).dtype == torch.float64
        assert SoftThreshold(0.3)(v).dtype == torch.float64

    def test_exception(self):
        with pytest.raises(DepthSRError, match="learnable threshold must be > 0"):
            SoftThreshold(0.0, learnable=True)
        with pytest.raises(DepthSRError, match=">= 0"):
            SoftThreshold(-1.0)
        with pytest.raises(ShapeError, match="per-sample 1-D"):
            SoftThreshold(torch.ones(2, 2))

    def test_softplus_roundtrip(self):
        t = torch.tensor([1e-3, 0.3, 5.0, 30.0])
        st = SoftThreshold(t, learnable=True)
        torch.testing.assert_close(F.softplus(st.raw), t, rtol=1e-4, atol=0)
