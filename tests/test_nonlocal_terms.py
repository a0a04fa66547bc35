"""nonlocal_terms: α and the value prior from one read of the matches; the numba kernel against the torch path."""
import pytest
import torch

from torch_depth_sr.block_matching import block_match
from torch_depth_sr.nonlocal_prior import nonlocal_gradient, nonlocal_terms
from torch_depth_sr.operators import grad


def _inputs(dtype, b=2, h=23, w=31):
    g = torch.Generator().manual_seed(0)
    yy = torch.linspace(0, 1, h).view(h, 1)
    xx = torch.linspace(0, 1, w).view(1, w)
    surface = 4 * yy + 3 * xx + 6 * (xx > 0.5)  # a slope with a step: both gates of the value prior act
    x = (surface + 0.3 * torch.randn(b, 1, h, w, generator=g)).to(dtype)
    m = block_match(x, None, None, block_size=3, search_window=7, k=5, temperature=0.5)
    return x, grad(x), m


def _loop(x, gx, m, weight, max_var, max_offset):
    """Pixel by pixel, straight from the definitions (model.md): α, W and x̄."""
    b, _, h, w = x.shape
    k = m.index.shape[1]
    alpha = torch.zeros_like(gx)
    diag = torch.zeros_like(x)
    target = torch.zeros_like(x)
    for n in range(b):
        for i in range(h):
            for j in range(w):
                om = m.weight[n, :, i, j].double()
                idx = m.index[n, :, i, j]
                xs = x[n, 0].flatten()[idx].double()
                xbar = (om * xs).sum()
                var = (om * (xs - xbar) ** 2).sum()
                oy = (om * (idx // w - i).double()).sum()
                ox = (om * (idx % w - j).double()).sum()
                for c in range(2):
                    alpha[n, c, i, j] = (om * gx[n, c].flatten()[idx].double()).sum()
                target[n, 0, i, j] = xbar
                diag[n, 0, i, j] = weight if (var < max_var and oy**2 + ox**2 <= max_offset**2) else 0.0
    return alpha, diag, target


@pytest.mark.parametrize("backend", ["auto", "torch"])
def test_matches_the_definitions(backend):
    x, gx, m = _inputs(torch.float64, b=1, h=9, w=11)
    alpha, diag, target = nonlocal_terms(x, gx, m, value_weight=10.0, max_var=0.5, max_offset=1.0, backend=backend)
    ra, rd, rt = _loop(x, gx, m, 10.0, 0.5, 1.0)
    torch.testing.assert_close(alpha, ra)
    torch.testing.assert_close(target, rt)
    torch.testing.assert_close(diag, rd)
    assert 0 < int((diag > 0).sum()) < diag.numel()  # the gates keep some pixels and drop others


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_numba_kernel_equals_torch_path(dtype):
    pytest.importorskip("numba")
    x, gx, m = _inputs(dtype)
    fast = nonlocal_terms(x, gx, m, value_weight=10.0, max_var=0.25, max_offset=2.5)
    ref = nonlocal_terms(x, gx, m, value_weight=10.0, max_var=0.25, max_offset=2.5, backend="torch")
    torch.testing.assert_close(fast[0], ref[0])
    torch.testing.assert_close(fast[2], ref[2])
    # the weight is a 0/η₃ mask: a pixel whose variance lies within round-off of the gate may flip in float32
    assert (fast[1] != ref[1]).float().mean() <= (0 if dtype == torch.float64 else 1e-3)
    assert all(t.dtype == dtype for t in fast)


def test_alpha_equals_nonlocal_gradient_and_options():
    x, gx, m = _inputs(torch.float64)
    alpha, diag, target = nonlocal_terms(x, gx, m)  # value_weight 0: no value prior
    torch.testing.assert_close(alpha, nonlocal_gradient(gx, m))
    assert diag is None and target is None
    a2, d2, t2 = nonlocal_terms(x, None, m, value_weight=1.0)
    assert a2 is None and d2 is not None and t2 is not None
    assert nonlocal_terms(x, None, m) == (None, None, None)


def test_gradients_flow_through_the_torch_path():
    """Autograd needs the torch path: x, D x and the weights get gradients (the kernel is used without them)."""
    x, _, m = _inputs(torch.float64, b=1, h=8, w=9)
    x = x.clone().requires_grad_(True)
    w = m.weight.clone().requires_grad_(True)

    def f(xx, ww):
        a, d, t = nonlocal_terms(xx, grad(xx), m._replace(weight=ww), value_weight=2.0, max_var=1e9, max_offset=1e9)
        return a.sum() + (d * t).sum()

    assert torch.autograd.gradcheck(f, (x, w))


def test_inputs_not_modified():
    x, gx, m = _inputs(torch.float32)
    before = [t.clone() for t in (x, gx, m.index, m.weight)]
    for backend in ("auto", "torch"):
        nonlocal_terms(x, gx, m, value_weight=10.0, backend=backend)
        assert all(torch.equal(a, b) for a, b in zip(before, (x, gx, m.index, m.weight)))


def _plane_loop(x, m, ridge):
    """x̄ and residual variance of the weighted ridge plane fit, pixel by pixel (numpy least squares)."""
    import numpy as np

    _, _, h, w = x.shape
    xbar, var = torch.zeros_like(x), torch.zeros_like(x)
    for i in range(h):
        for j in range(w):
            om = m.weight[0, :, i, j].double().numpy()
            om = om / om.sum()
            idx = m.index[0, :, i, j].numpy()
            xs = x[0, 0].flatten()[idx].double().numpy()
            d = np.stack([idx // w - i, idx % w - j], 1).astype(float)
            dc = d - om @ d
            xc = xs - om @ xs
            # minimise Σ ω (xc − g·dc)² + ridge |g|², then the plane's value at the pixel (offset 0)
            g = np.linalg.solve(dc.T @ (om[:, None] * dc) + ridge * np.eye(2), dc.T @ (om * xc))
            xbar[0, 0, i, j] = om @ xs - (om @ d) @ g
            var[0, 0, i, j] = max(om @ (xc - dc @ g) ** 2, 0.0)
    return xbar, var


@pytest.mark.parametrize("backend", ["auto", "torch"])
def test_plane_fit_matches_least_squares(backend):
    x, gx, m = _inputs(torch.float64, b=1, h=9, w=11)
    _, diag, target = nonlocal_terms(x, gx, m, value_weight=1.0, max_var=1e9, max_offset=1e9, plane_ridge=0.5,
                                     backend=backend)
    ref, _ = _plane_loop(x, m, 0.5)
    torch.testing.assert_close(target, ref)
    _, diag, _ = nonlocal_terms(x, gx, m, value_weight=1.0, max_var=0.05, max_offset=1e9, plane_ridge=0.5,
                                backend=backend)
    _, ref_var = _plane_loop(x, m, 0.5)
    torch.testing.assert_close(diag, (ref_var < 0.05).to(diag.dtype))


def test_plane_fit_is_unbiased_on_a_slope_where_the_mean_is_not():
    # a clean slope: the matched centres of a border pixel lie on one side, so their mean is off by the slope
    # times the centroid's distance; the plane through them passes through the pixel's own value
    h, w = 12, 14
    yy, xx = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    x = (0.8 * yy + 0.5 * xx + 0.02 * yy * xx)[None, None]
    m = block_match(x, None, None, block_size=3, search_window=7, k=6, temperature=0.5)
    kw = dict(value_weight=1.0, max_var=1e9, max_offset=1e9)
    _, _, mean = nonlocal_terms(x, None, m, **kw)
    _, _, plane = nonlocal_terms(x, None, m, plane_ridge=1e-3, **kw)
    assert float((mean - x).abs().max()) > 0.5
    assert float((plane - x).abs().max()) < 0.2
    pytest.importorskip("numba")
    fast = nonlocal_terms(x.float(), None, m, plane_ridge=0.5, **kw)
    ref = nonlocal_terms(x.float(), None, m, plane_ridge=0.5, backend="torch", **kw)
    torch.testing.assert_close(fast[2], ref[2])


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_range_weights_kernel_equals_torch_path_and_spare_alpha(dtype):
    x, gx, m = _inputs(dtype)
    rs = torch.full_like(x, 0.8)
    rs[..., :5, :] = 0  # no range weights there
    kw = dict(value_weight=1.0, max_var=0.25, max_offset=6.0, plane_ridge=1.0, range_sigma=rs)
    ref = nonlocal_terms(x, gx, m, backend="torch", **kw)
    plain = nonlocal_terms(x, gx, m, backend="torch", **{**kw, "range_sigma": None})
    torch.testing.assert_close(ref[0], plain[0])  # α keeps the match weights
    torch.testing.assert_close(ref[2][..., :5, :], plain[2][..., :5, :])
    assert float((ref[2] - plain[2]).abs().max()) > 1e-3  # the step is where the range weights act
    pytest.importorskip("numba")
    fast = nonlocal_terms(x, gx, m, **kw)
    torch.testing.assert_close(fast[0], ref[0])
    torch.testing.assert_close(fast[2], ref[2])


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_a_region_gets_the_values_of_every_pixel_computed(dtype):
    """``region``: the numba kernel computes its pixels alone, with the values a whole-frame call gives them; the
    other pixels are 0."""
    pytest.importorskip("numba")
    x, gx, m = _inputs(dtype)
    region = torch.rand(x.shape, generator=torch.Generator().manual_seed(3)) < 0.3
    region[0, 0, 4:9, 10:30] = True  # runs of region pixels longer than one
    kw = dict(value_weight=10.0, max_var=0.25, max_offset=2.5, plane_ridge=0.1, range_sigma=1.0)
    full = nonlocal_terms(x, gx, m, **kw)
    part = nonlocal_terms(x, gx, m, region=region, **kw)
    for a, b in zip(full, part):
        r = region.expand_as(a)
        assert torch.equal(b[r], a[r])
    alpha = part[0]
    assert not alpha[~region.expand_as(alpha)].any() and alpha[region.expand_as(alpha)].abs().sum() > 0
