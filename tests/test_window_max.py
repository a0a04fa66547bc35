"""window_max: the separable window maximum equals torch's max_pool2d bit for bit, and keeps its gradient; the
bool dilation's numba kernel (dilate_kernel.py) gives the torch path's mask."""
import pytest
import torch
import torch.nn.functional as F

from torch_depth_sr import window_max
from torch_depth_sr.window_max import max_filter, min_filter


@pytest.mark.parametrize("size", [1, 3, 5, 7])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_same_values_as_max_pool(size, dtype):
    g = torch.Generator().manual_seed(size)
    x = torch.randint(0, 7, (2, 3, 13, 17), generator=g).to(dtype)  # many ties
    x[0, 1, 4, 5] = float("nan")
    for pad in (size // 2, 0):
        ref = F.max_pool2d(x, size, stride=1, padding=pad)
        assert torch.equal(max_filter(x, size, padding=pad).isnan(), ref.isnan())
        assert torch.equal(torch.nan_to_num(max_filter(x, size, padding=pad)), torch.nan_to_num(ref))
        assert torch.equal(min_filter(x, size, padding=pad).nan_to_num(), (-F.max_pool2d(-x, size, 1, pad)).nan_to_num())


def test_gradient_goes_to_one_argmax_as_max_pool():
    x = torch.zeros(1, 1, 4, 4, requires_grad=True)  # every window a tie
    max_filter(x, 3).sum().backward()
    y = torch.zeros(1, 1, 4, 4, requires_grad=True)
    F.max_pool2d(y, 3, 1, 1).sum().backward()
    assert torch.equal(x.grad, y.grad)


def test_input_not_modified():
    x = torch.rand(1, 1, 8, 8)
    before = x.clone()
    min_filter(max_filter(x, 5), 3)
    assert torch.equal(x, before)


@pytest.mark.parametrize("shape", [(1, 1, 1, 1), (1, 1, 5, 3), (2, 1, 40, 150), (1, 2, 70, 9)])
@pytest.mark.parametrize("radius", [1, 3, 8])
def test_dilate_kernel_equals_torch(monkeypatch, shape, radius):
    mask = torch.rand(shape, generator=torch.Generator().manual_seed(radius)) > 0.97
    out = window_max.dilate(mask, radius)
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    ref = window_max.dilate(mask, radius)
    assert out.dtype == torch.bool and torch.equal(out, ref)
    assert bool(ref[mask].all())  # the set pixels stay set


@pytest.mark.parametrize("where", [(), ((3, 4),), ((0, 0), (2, 70)), ((55, 140), (57, 149))])
@pytest.mark.parametrize("radius", [1, 4])
def test_dilate_kernel_of_a_sparse_mask_equals_torch(monkeypatch, where, radius):
    """Mostly empty masks (a stream's), set pixels at the border."""
    mask = torch.zeros(2, 1, 60, 150, dtype=torch.bool)
    for i, (r, c) in enumerate(where):
        mask[i % 2, 0, r, c] = True
    out = window_max.dilate(mask, radius)
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    assert torch.equal(out, window_max.dilate(mask, radius))
