"""A crop's block matches: the numba kernel (stream/matches_kernel.py) gives the torch path's indices and weights bit
for bit, for both ways of treating a match that leaves the crop."""
import pytest
import torch

from torch_depth_sr.block_matching import BlockMatches
from torch_depth_sr.stream.matching import crop_matches


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("outside", ["own", "missing"])
@pytest.mark.parametrize("crop", [(slice(0, 37), slice(0, 70)), (slice(5, 20), slice(11, 64)),
                                  (slice(36, 37), slice(3, 4))])
def test_crop_matches_kernel_equals_torch(monkeypatch, dtype, outside, crop):
    g = torch.Generator().manual_seed(crop[0].start + crop[1].start)
    b, k, h, w = 2, 5, 37, 70
    index = torch.randint(-1, h * w, (b, k, h, w), generator=g)  # -1: a missing match
    weight = torch.rand(b, k, h, w, generator=g, dtype=dtype)
    m = BlockMatches(torch.rand(b, k, h, w, generator=g, dtype=dtype), index, weight)
    out = crop_matches(m, *crop, w, outside=outside)
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    ref = crop_matches(m, *crop, w, outside=outside)
    hc, wc = crop[0].stop - crop[0].start, crop[1].stop - crop[1].start
    assert out.index.shape == (b, k, hc, wc) and out.index.dtype == torch.int64
    assert torch.equal(out.index, ref.index) and torch.equal(out.weight, ref.weight)
    assert torch.equal(out.dist, ref.dist)
    moved = ((ref.index >= 0) & (ref.index < hc * wc) & (ref.weight > 0)).any()
    assert bool(moved) or hc * wc == 1  # some matches stay in the crop
    assert (outside == "own") != bool((ref.index == -1).any())  # and some leave it


def test_crop_matches_with_gradient_take_torch_path():
    index = torch.zeros(1, 1, 4, 4, dtype=torch.int64)
    weight = torch.rand(1, 1, 4, 4, requires_grad=True)
    m = BlockMatches(torch.rand(1, 1, 4, 4), index, weight)
    out = crop_matches(m, slice(1, 3), slice(1, 3), 4, outside="own")
    out.weight.sum().backward()  # the torch path keeps the weights' gradient
    assert weight.grad is not None
