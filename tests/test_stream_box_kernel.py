"""The stream's window means: the numba kernel (stream/box_kernel.py) gives the torch path's means bit for bit."""
import pytest
import torch

from torch_depth_sr.stream import change


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("shape,window", [((1, 1, 5, 3), 3), ((1, 1, 2, 2), 7), ((2, 3, 37, 70), 3),
                                          ((1, 2, 130, 9), 7), ((1, 1, 1, 1), 1)])
def test_kernel_equals_torch_path(monkeypatch, dtype, shape, window):
    v = 100 * torch.randn(shape, generator=torch.Generator().manual_seed(sum(shape)), dtype=dtype)
    out = change._box_mean(v, window)
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    ref = change._box_mean(v, window)
    assert out.dtype == dtype and torch.equal(out, ref)


def test_gradient_takes_the_torch_path():
    v = torch.rand(1, 1, 6, 7, dtype=torch.float64, requires_grad=True)
    change._box_mean(v, 3).sum().backward()
    assert v.grad is not None and bool((v.grad > 0).all())


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("shape,channels,window", [((1, 1, 1, 1), 1, 3), ((2, 1, 6, 5), 2, 7), ((1, 1, 40, 150), 2, 7)])
def test_local_spread_kernel_equals_torch(monkeypatch, dtype, shape, channels, window):
    from torch_depth_sr.stream.change import local_spread

    g = torch.Generator().manual_seed(window + sum(shape))
    y = 1000 * torch.rand(shape, generator=g, dtype=dtype)
    observed = (torch.rand(shape, generator=g) > 0.3).to(dtype)
    observed[..., :3, :3] = 0  # a window with no measured pixel
    y = y * observed
    x = y + torch.randn(shape[0], channels, *shape[2:], generator=g, dtype=dtype)
    out = local_spread(y, observed, x, window)
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    ref = local_spread(y, observed, x, window)
    assert out.dtype == dtype and out.shape == ref.shape and torch.equal(out, ref)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("shape,window", [((1, 1, 1, 1), 3), ((2, 1, 6, 5), 7), ((1, 1, 40, 150), 7)])
def test_remembered_spread_kernel_equals_torch(monkeypatch, dtype, shape, window):
    from torch_depth_sr.stream.change import remembered_spread

    g = torch.Generator().manual_seed(window + sum(shape))
    observed = (torch.rand(shape, generator=g) > 0.3).to(dtype)
    observed[..., :3, :3] = 0
    y = 1000 * torch.rand(shape, generator=g, dtype=dtype) * observed
    x, past = y + torch.randn(shape, generator=g, dtype=dtype), y + 3 * torch.randn(shape, generator=g, dtype=dtype)
    past_spread = 4 * torch.rand(shape, generator=g, dtype=dtype)
    static = torch.rand(shape, generator=g) > 0.4
    out = remembered_spread(y, observed, x, past, past_spread, static, window, 0.9)
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    ref = remembered_spread(y, observed, x, past, past_spread, static, window, 0.9)
    assert out.dtype == dtype and out.shape == ref.shape and torch.equal(out, ref)
