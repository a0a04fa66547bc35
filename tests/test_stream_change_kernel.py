"""The change test's nearest distances, votes and colour change: the numba kernels (stream/change_kernel.py) give the
torch path's results bit for bit."""
import pytest
import torch

from torch_depth_sr.stream import change


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
    assert native.host_kernel("dilate_kernel", "dilate_cpu", x > 0.5, dtypes=(torch.bool,)) is not None
    monkeypatch.setenv("TORCH_DEPTH_SR_DEVICE_PATH", "1")
    assert native.host_kernel("stream.box_kernel", "box_mean_cpu", x) is None


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("shape", [(1, 3, 1, 1), (2, 3, 5, 4), (1, 3, 40, 61)])
def test_colour_changes_kernel_equals_torch(monkeypatch, dtype, shape):
    g = torch.Generator().manual_seed(sum(shape))
    rgb, previous = torch.rand(shape, generator=g, dtype=dtype), torch.rand(shape, generator=g, dtype=dtype)
    previous = torch.where(torch.rand(shape, generator=g) > 0.5, rgb + 0.02, previous)  # near the test, and far
    out = change.colour_changes(rgb, previous, 3, 0.03)
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    ref = change.colour_changes(rgb, previous, 3, 0.03)
    assert torch.equal(out[0], ref[0]) and out[1].dtype == torch.bool and torch.equal(out[1], ref[1])
    if shape[-1] > 4:
        assert bool(ref[1].any()) and not bool(ref[1].all())


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("shape,shift", [((1, 3, 5, 6), (0, 0)), ((2, 3, 40, 61), (1, -2)), ((1, 3, 90, 120), (0, 1))])
def test_camera_moved_kernel_equals_torch_to_float32_rounding(monkeypatch, dtype, shape, shift):
    """The kernel sums in float64 where torch's means sum float32 values: the ratios agree to float32 rounding."""
    g = torch.Generator().manual_seed(sum(shape))
    previous = torch.rand(shape, generator=g, dtype=dtype)
    rgb = torch.roll(previous, shift, dims=(-2, -1)) + 0.01 * torch.rand(shape, generator=g, dtype=dtype)
    out = change.camera_moved(rgb, previous)
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    ref = change.camera_moved(rgb, previous)
    assert out.dtype == ref.dtype == dtype and out.shape == ref.shape
    assert torch.allclose(out, ref, rtol=1e-5, atol=0)
    if shift != (0, 0) and shape[-1] > 6:
        assert bool((ref < 0.8).all())  # a shifted image: the camera moved
