"""The shift test of a stream's change test (stream/shift.py): an edge that moved by a pixel is a change, a mixed pixel
at an edge that stayed is not; the numba kernel gives the torch path's verdicts bit for bit."""
import pytest
import torch

from torch_depth_sr.config import StreamConfig
from torch_depth_sr.stream import change
from torch_depth_sr.stream.shift import shifted_windows


def _step_edge(h=20, w=24, column=12, near=500.0, far=1500.0):
    d = torch.full((1, 1, h, w), far)
    d[..., :column] = near
    return d


def test_an_edge_that_moved_by_one_pixel_is_found():
    previous, now = _step_edge(column=12), _step_edge(column=13)
    found = shifted_windows(now, torch.ones_like(now), previous, torch.full_like(now, 5.0), 0.5)
    assert bool(found[..., 5:15, 12].all())  # the column the edge crossed
    assert not bool(found[..., :, :8].any()) and not bool(found[..., :, 18:].any())  # far from the edge: nothing


def test_a_mixed_pixel_at_an_edge_that_stayed_is_not_a_shift():
    previous = _step_edge(column=12)
    now = previous.clone()
    now[..., 10, 12] = 500.0  # one pixel takes the other side's depth
    found = shifted_windows(now, torch.ones_like(now), previous, torch.full_like(now, 5.0), 0.5)
    assert not bool(found.any())


def test_noise_alone_is_no_shift():
    g = torch.Generator().manual_seed(0)
    previous = _step_edge()
    now = previous + 5.0 * torch.randn(previous.shape, generator=g)
    assert not bool(shifted_windows(now, torch.ones_like(now), previous, torch.full_like(now, 5.0), 0.5).any())


def test_the_depth_test_alone_misses_a_one_pixel_move_and_the_change_test_finds_it():
    """The depth test's nearest previous value within one pixel hides the move; the shift test does not."""
    previous, now = _step_edge(column=12), _step_edge(column=13)
    noise = torch.full_like(now, 5.0)
    without = change.change_test(now, torch.ones_like(now), previous, noise, None, None,
                                 StreamConfig(shift_test=None))
    with_test = change.change_test(now, torch.ones_like(now), previous, noise, None, None, StreamConfig())
    assert not bool(without.changed.any())
    assert bool(with_test.changed[..., 10, 10:16].all())


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("shape", [(1, 1, 1, 1), (1, 1, 3, 4), (2, 1, 37, 70), (1, 1, 90, 9)])
def test_the_kernel_equals_the_torch_path(monkeypatch, dtype, shape):
    g = torch.Generator().manual_seed(sum(shape))
    previous = 1000 * torch.rand(shape, generator=g, dtype=dtype).round(decimals=1)
    now = previous.roll(1, -1) + torch.randn(shape, generator=g, dtype=dtype)
    now[..., : shape[-2] // 2, :] = previous[..., : shape[-2] // 2, :] + 3 * torch.randn(
        (*shape[:-2], shape[-2] // 2, shape[-1]), generator=g, dtype=dtype)  # the top half still
    observed = (torch.rand(shape, generator=g) > 0.2).to(dtype)
    noise = 0.5 + 20 * torch.rand(shape, generator=g, dtype=dtype)
    out = shifted_windows(now, observed, previous, noise, 0.5)
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    ref = shifted_windows(now, observed, previous, noise, 0.5)
    assert out.dtype == torch.bool and out.shape == ref.shape and torch.equal(out, ref)
    if min(shape[-2:]) > 8:
        assert bool(ref.any()) and not bool(ref.all())  # the test compares verdicts of both kinds


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("ratio", [0.25, 0.5, 0.9, 1.0])
def test_the_kernel_equals_the_torch_path_with_flying_pixels(monkeypatch, dtype, ratio):
    """Impulses on a still surface and an edge that moved: the kernel skips a window whose pixels' smallest errors
    over the shifts already reach the bound, the torch path sums every shift; the verdicts are the same."""
    g = torch.Generator().manual_seed(int(100 * ratio))
    shape = (2, 1, 48, 64)
    previous = 500 + 40 * torch.rand(shape, generator=g, dtype=dtype)
    previous[..., 20:] += 300  # a depth edge
    now = previous + torch.randn(shape, generator=g, dtype=dtype)
    now[0, :, 20:] = previous[0, :, 19:-1] + torch.randn((1, 28, 64), generator=g, dtype=dtype)  # moved by a row
    flying = torch.rand(shape, generator=g) < 0.02
    now = torch.where(flying, now + 150 * torch.rand(shape, generator=g, dtype=dtype), now)
    observed = (torch.rand(shape, generator=g) > 0.1).to(dtype)
    noise = torch.full(shape, 4.0, dtype=dtype)
    out = shifted_windows(now, observed, previous, noise, ratio)
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    ref = shifted_windows(now, observed, previous, noise, ratio)
    assert torch.equal(out, ref)
    assert bool(ref[0].any()) and not bool(ref.all())


def test_unmeasured_pixels_are_never_marked():
    previous, now = _step_edge(column=12), _step_edge(column=13)
    observed = torch.ones_like(now)
    observed[..., :, 13] = 0
    found = shifted_windows(now, observed, previous, torch.full_like(now, 5.0), 0.5)
    assert not bool(found[observed == 0].any())
