"""The numba kernels of the edge steps (edge_snap_kernel.py) against the torch path (edge_snap.py), the reference:
the same medians (as values: among equal values the torch sort order is arbitrary), the same shares to round-off,
the same refitted pixels; any thread count gives the same results."""
import pytest
import torch
import torch.nn.functional as F

pytest.importorskip("numba")

from torch_depth_sr import edge_snap, native  # noqa: E402
from torch_depth_sr.edge_snap import refit_to_measurements, sided_median, snap_to_sides  # noqa: E402

pytestmark = pytest.mark.skipif(native.numba_disabled(), reason="TORCH_DEPTH_SR_NO_NUMBA is set")


def _scene(dtype, b=2, h=23, w=31, seed=0):
    """Two planes with a step edge, quantised (ties), holes; a colour edge near the depth edge, and noise."""
    g = torch.Generator().manual_seed(seed)
    yy, xx = torch.meshgrid(torch.arange(h, dtype=dtype), torch.arange(w, dtype=dtype), indexing="ij")
    left = xx < w // 2 + (yy // 5)
    depth = torch.where(left, 20 + 0.3 * xx + 0.2 * yy, 60 - 0.1 * xx)
    x = (depth + 2 * torch.randn(b, 1, h, w, generator=g, dtype=dtype)).round()
    rgb = torch.where(left, 0.2, 0.7) + 0.1 * torch.rand(b, 3, h, w, generator=g, dtype=dtype)
    observed = (torch.rand(b, 1, h, w, generator=g) > 0.15).to(dtype)
    y = (x + torch.randn(b, 1, h, w, generator=g, dtype=dtype)).round() * observed
    x[:, :, 5:7, 3:5] = 40.0  # a few blends between the sides
    return x, rgb, y, observed


def _spatial(r, sigma_space, dtype):
    if sigma_space is None:
        return None
    return torch.tensor([-(dy * dy + dx * dx) / (2.0 * sigma_space ** 2) for dy in range(-r, r + 1)
                         for dx in range(-r, r + 1)], dtype=dtype).exp().view(1, -1, 1, 1)


def _near_edge(x, edge, r):
    near = (F.max_pool2d(x, 5, 1, 2) + F.max_pool2d(-x, 5, 1, 2)) > edge
    where = near.nonzero()
    b, _, h, w = x.shape
    return near, where[:, 0] * h * w + where[:, 2] * w + where[:, 3]


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("radius,sigma_space", [(1, None), (2, None), (2, 1.5), (3, 2.0)])
def test_sided_median_matches_the_torch_path(dtype, radius, sigma_space):
    x, rgb, _, _ = _scene(dtype)
    median, share = sided_median(x, rgb, radius, 0.235, sigma_space)
    ref_median, ref_share = edge_snap._sided_median_torch(x, rgb, radius, 0.235, _spatial(radius, sigma_space, dtype))
    assert median.dtype == dtype and median.shape == x.shape
    assert torch.equal(median, ref_median)  # the border pixels too (the cut, point-symmetric window)
    rtol = 1e-5 if dtype == torch.float32 else 1e-12
    torch.testing.assert_close(share, ref_share, rtol=rtol, atol=rtol)
    assert (share > 0.6).sum() > 0 and (share < 0.6).sum() > 0  # both kinds of pixel are compared


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("cutoff", [0.3, 0.55, 0.599])
def test_the_cutoff_skips_only_pixels_whose_share_cannot_exceed_it(dtype, cutoff):
    """snap_to_sides's shortcut: with a cutoff, a pixel reports (x_i, 0) only where its full share is at most the
    cutoff; every other pixel reports the full median and share, bit for bit."""
    from torch_depth_sr.edge_snap_kernel import sided_median_cpu
    x, rgb, _, _ = _scene(dtype, h=40, w=50, seed=4)
    spatial = _spatial(2, 1.5, dtype)
    median, share = sided_median_cpu(x, rgb, 2, 0.235, spatial)
    cut_median, cut_share = sided_median_cpu(x, rgb, 2, 0.235, spatial, cutoff)
    skipped = (cut_share == 0) & (share > 0)
    assert skipped.sum() > 0 and (~skipped).sum() > 0  # both kinds of pixel
    assert bool((share[skipped] <= cutoff + 1e-6).all())
    assert torch.equal(cut_median[skipped], x[skipped])
    kept = ~skipped
    assert torch.equal(cut_median[kept], median[kept]) and torch.equal(cut_share[kept], share[kept])
    assert bool((share > cutoff + 1e-6).le(kept).all())  # no pixel that could move was skipped


@pytest.mark.parametrize("active", [None, "pixels", "samples"])
def test_snap_to_sides_matches_the_torch_path(active):
    x, rgb, _, _ = _scene(torch.float32)
    if active == "pixels":
        active = torch.rand(x.shape, generator=torch.Generator().manual_seed(3)) > 0.3
    elif active == "samples":
        active = torch.tensor([False, True]).view(2, 1, 1, 1)
    snapped = snap_to_sides(x, rgb, rounds=2, active=active)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
        reference = snap_to_sides(x, rgb, rounds=2, active=active)
    assert (snapped != x).sum() > 10 and torch.equal(snapped, reference)


@pytest.mark.parametrize("active", [None, "pixels", "samples"])
@pytest.mark.parametrize("edge", [10.0, 16.0])
def test_snap_near_edges_matches_the_torch_path_and_moves_only_there(active, edge):
    """``edge``: the kernel sorts only the windows near a depth edge (weights computed where read, not as planes);
    the torch path computes every window and keeps the moves near an edge. Same result, and no pixel away from an
    edge moves (with every pixel allowed, some do)."""
    x, rgb, _, _ = _scene(torch.float32, h=40, w=50, seed=2)
    if active == "pixels":
        active = torch.rand(x.shape, generator=torch.Generator().manual_seed(3)) > 0.3
    elif active == "samples":
        active = torch.tensor([False, True]).view(2, 1, 1, 1)
    snapped = snap_to_sides(x, rgb, rounds=1, active=active, edge=edge)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
        reference = snap_to_sides(x, rgb, rounds=1, active=active, edge=edge)
    assert (snapped != x).sum() > 5 and torch.equal(snapped, reference)
    near, _ = _near_edge(x, edge, 2)
    everywhere = snap_to_sides(x, rgb, rounds=1, active=active)
    assert bool((snapped != x).le(near).all()) and ((everywhere != x) & ~near).sum() > 0
    assert torch.equal(snapped[near], everywhere[near])  # near an edge, the same moves as without ``edge``


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("radius", [1, 3, 5])
def test_refit_matches_the_torch_path(dtype, radius):
    x, rgb, y, observed = _scene(dtype)
    out = refit_to_measurements(x, y, observed, rgb, radius=radius, band=1.5, edge=2.0)
    near, pixels = _near_edge(x, 2.0, radius)
    reference = edge_snap._refit_torch(x, y, observed, rgb, near, pixels, radius, 1.5, 0.235)
    assert out.dtype == dtype
    moved = (out != x).sum()
    assert moved > 20 and moved == (reference != x).sum()
    assert torch.equal(out, reference)


def test_refit_with_active_samples_matches_the_torch_path():
    x, rgb, y, observed = _scene(torch.float64)
    active = torch.tensor([True, False]).view(2, 1, 1, 1)
    out = refit_to_measurements(x, y, observed, rgb, radius=3, band=2.0, edge=3.0, active=active)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
        reference = refit_to_measurements(x, y, observed, rgb, radius=3, band=2.0, edge=3.0, active=active)
    assert torch.equal(out[1], x[1]) and (out[0] != x[0]).sum() > 0
    assert torch.equal(out, reference)


def test_the_kernels_give_the_same_results_on_one_and_two_threads():
    x, rgb, y, observed = _scene(torch.float32, h=41, w=57, seed=1)
    old = torch.get_num_threads()
    results = []
    try:
        for n in (1, 2):
            torch.set_num_threads(n)
            results.append((*sided_median(x, rgb, 2, 0.235, 1.5),
                             refit_to_measurements(x, y, observed, rgb, radius=5, band=1.5, edge=2.0)))
    finally:
        torch.set_num_threads(old)
    for a, b in zip(*results):
        assert torch.equal(a, b)


def test_autograd_and_other_dtypes_take_the_torch_path(monkeypatch):
    calls = []
    real = native.cpu_kernel
    monkeypatch.setattr(native, "cpu_kernel", lambda *a, **k: calls.append(a[1]) or real(*a, **k))  # host_kernel asks it
    x, rgb, y, observed = _scene(torch.float64, h=9, w=11)
    x.requires_grad_(True)
    median, _ = sided_median(x, rgb, 1)
    median.sum().backward()  # through the selection: the torch path
    assert x.grad is not None and calls == []
    sided_median(x.detach().half(), rgb.half(), 1)
    assert calls == []
    with torch.no_grad():
        sided_median(x, rgb, 1)
    assert calls == ["sided_median_cpu"]
