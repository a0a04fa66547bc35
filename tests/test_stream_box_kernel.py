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
