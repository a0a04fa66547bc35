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


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("shape,window", [((1, 1, 1, 1), 3), ((1, 1, 4, 3), 7), ((2, 1, 37, 150), 7), ((1, 1, 90, 9), 5)])
def test_vote_counts_kernel_equals_torch(monkeypatch, dtype, shape, window):
    g = torch.Generator().manual_seed(window + sum(shape))
    d1 = 6 * torch.rand(shape, generator=g, dtype=dtype)
    observed = (torch.rand(shape, generator=g) > 0.3).to(dtype)
    out = change.depth_votes(d1, observed, window, 2.7)  # not a float32: compared in the frame's dtype, as torch does
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    ref = change.depth_votes(d1, observed, window, 2.7)
    assert out.dtype == dtype and out.shape == ref.shape and torch.equal(out, ref)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("shape,window", [((1, 3, 1, 1), 3), ((2, 3, 5, 4), 7), ((1, 3, 40, 61), 7)])
def test_colour_change_equals_its_window_mean_form(monkeypatch, dtype, shape, window):
    """color_change divides by the windows' in-image shares from counts: the weighted window mean of before."""
    g = torch.Generator().manual_seed(window + sum(shape))
    rgb, previous = torch.rand(shape, generator=g, dtype=dtype), torch.rand(shape, generator=g, dtype=dtype)
    out = change.color_change(rgb, previous, window)
    for numba in ("0", "1"):
        monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", numba)
        diff = rgb - previous
        diff = diff - diff.flatten(2).median(-1).values[..., None, None]
        num, den = change._window_mean(diff.abs().mean(1, keepdim=True), window)
        assert torch.equal(out, num / den)


def test_the_kernel_gate_takes_the_torch_path_for_gradients_other_dtypes_and_the_device_path(monkeypatch):
    """native.host_kernel: the one gate of the kernels that keep the torch path's values."""
    from torch_depth_sr import native

    x = torch.rand(1, 1, 4, 5, dtype=torch.float64)
    assert native.host_kernel("stream.box_kernel", "box_mean_cpu", x) is not None
    assert native.host_kernel("stream.box_kernel", "box_mean_cpu", x.half()) is None
    assert native.host_kernel("stream.box_kernel", "box_mean_cpu", x, x.clone().requires_grad_()) is None
    with torch.no_grad():
        assert native.host_kernel("stream.box_kernel", "box_mean_cpu", x.clone().requires_grad_()) is not None
    assert native.host_kernel("stream.change_kernel", "dilate_cpu", x > 0.5, dtypes=(torch.bool,)) is not None
    monkeypatch.setenv("TORCH_DEPTH_SR_DEVICE_PATH", "1")
    assert native.host_kernel("stream.box_kernel", "box_mean_cpu", x) is None
