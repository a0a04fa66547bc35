"""The domain-transform filter's numba box kernels (domain_kernel.py) give the torch path's output bit for bit."""
import pytest
import torch

from torch_depth_sr.guided_filters import domain_transform_filter


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("shape,iterations", [((1, 1, 5, 3), 1), ((2, 1, 37, 50), 1), ((2, 1, 64, 70), 2),
                                              ((1, 1, 130, 9), 3)])
def test_kernel_equals_torch_path(monkeypatch, dtype, shape, iterations):
    g = torch.Generator().manual_seed(sum(shape))
    b, _, h, w = shape
    depth = 100 + 10 * torch.rand(shape, generator=g, dtype=dtype)
    depth[torch.rand(shape, generator=g) < 0.3] = 0  # holes: the fill passes run too
    rgb = torch.rand(b, 3, h, w, generator=g, dtype=dtype)
    rgb[..., w // 2:] += 0.5  # a colour edge
    sigma = torch.tensor([3.0, 8.0][:b], dtype=dtype)  # per sample: different radii in one call
    out = domain_transform_filter(depth, rgb, sigma_space=sigma, sigma_color=0.1, iterations=iterations)
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    ref = domain_transform_filter(depth, rgb, sigma_space=sigma, sigma_color=0.1, iterations=iterations)
    assert torch.equal(out, ref)


def test_gradient_takes_the_torch_path():
    depth = (100 + torch.rand(1, 1, 12, 14, dtype=torch.float64)).requires_grad_()
    out = domain_transform_filter(depth, torch.rand(1, 3, 12, 14, dtype=torch.float64))
    out.sum().backward()
    assert depth.grad is not None and torch.isfinite(depth.grad).all()
