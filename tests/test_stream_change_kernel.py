"""The change test's nearest distances and dilation: the numba kernels (stream/change_kernel.py) give the torch
path's results bit for bit."""
import pytest
import torch

from torch_depth_sr.stream import change, matching


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("shape", [(1, 1, 1, 1), (1, 1, 2, 3), (2, 1, 37, 70), (1, 1, 130, 9)])
@pytest.mark.parametrize("per_pixel", [False, True])
def test_nearest_distance_kernel_equals_torch(monkeypatch, dtype, shape, per_pixel):
    g = torch.Generator().manual_seed(sum(shape))
    y = 100 * torch.rand(shape, generator=g, dtype=dtype)
    observed = (torch.rand(shape, generator=g) > 0.2).to(dtype)
    previous = y + torch.randn(shape, generator=g, dtype=dtype)
    noise = (0.5 + torch.rand(shape if per_pixel else (shape[0], 1, 1, 1), generator=g, dtype=dtype))
    out = change._nearest_distance(y, observed, previous, noise)
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    ref = change.distances(y, observed, previous, noise)[1]
    assert out.dtype == dtype and out.shape == ref.shape and torch.equal(out, ref)


@pytest.mark.parametrize("shape", [(1, 1, 1, 1), (1, 1, 5, 3), (2, 1, 40, 150), (1, 2, 70, 9)])
@pytest.mark.parametrize("radius", [1, 3, 8])
def test_dilate_kernel_equals_torch(monkeypatch, shape, radius):
    mask = torch.rand(shape, generator=torch.Generator().manual_seed(radius)) > 0.97
    out = matching.dilate(mask, radius)
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    ref = matching.dilate(mask, radius)
    assert out.dtype == torch.bool and torch.equal(out, ref)
    assert bool(ref[mask].all())  # the set pixels stay set
