"""The numba kernel of the hole fill's passes (fill_kernel.py) against the torch reference (fill._fill_pixels).

Inputs: two slanted planes with a step between them, a steep ramp (whose windows span a gap without a step: the
2-means iterate), a colour guide whose edge is off the depth's by a pixel (and a patch of a colour no neighbour has:
weak pixels), holes of every size: scattered pixels, a band along the step, blocks deeper than the window (several
passes). Quantized depth makes ties in the quantiles' ranks and the 2-means. Exact ties between the two sides'
masses pick a side by each path's summation order: those pixels (share within round-off of 1/2) may differ.
"""
import pytest
import torch

pytest.importorskip("numba")

from torch_depth_sr import fill, native  # noqa: E402
from torch_depth_sr.fill import _FillPlanes, _fill_pixels, fill_holes_sided  # noqa: E402

pytestmark = pytest.mark.skipif(native.numba_disabled(), reason="TORCH_DEPTH_SR_NO_NUMBA is set")


def _case(seed, dtype, guide=True, quantize=False, b=2, h=48, w=64):
    g = torch.Generator().manual_seed(seed)
    yy, xx = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    edge = w * 0.5 + 0.15 * (yy - h / 2)  # a slanted step
    right = xx > edge
    d = torch.where(right, 60.0 + 0.1 * xx - 0.05 * yy, 20.0 + 0.05 * xx + 0.08 * yy)
    d = torch.where((yy >= h - 12) & ~right, 20.0 + 1.5 * xx + 0.7 * (yy % 3), d)  # steep: the 2-means iterate
    d = d.expand(b, 1, h, w) + 0.3 * torch.randn(b, 1, h, w, generator=g, dtype=torch.float64)
    if quantize:
        d = (d * 2).round() / 2  # steps of 0.5: many equal values
    hole = torch.rand(b, 1, h, w, generator=g) < 0.06  # scattered pixels
    hole |= (xx - edge).abs().lt(1.6).expand(b, 1, h, w) & (yy > 5).expand(b, 1, h, w)  # a band along the step
    hole[..., 8:30, 4:26] = True  # deeper than the window: several passes
    hole[0, :, 30:44, 40:62] = True
    m = (~hole).to(dtype)
    y = torch.where(hole, torch.zeros_like(d), d).to(dtype)
    rgb = None
    if guide:
        cright = (xx > edge + 1).expand(b, 1, h, w)  # the colour edge one pixel off the depth's
        base = torch.where(cright, torch.tensor([0.7, 0.3, 0.2], dtype=torch.float64)[:, None, None],
                           torch.tensor([0.2, 0.4, 0.6], dtype=torch.float64)[:, None, None])
        rgb = (base + 0.01 * torch.randn(b, 3, h, w, generator=g, dtype=torch.float64)).to(dtype)
        rgb[-1, :, 10:20, 44:54] = torch.tensor([0.9, 0.9, 0.1], dtype=dtype)[:, None, None]  # colours no neighbour has
    return y, m, rgb


def _settings(kernel_size, choice):
    return dict(kernel_size=kernel_size, sigma_space=6.0, sigma_color=0.025, gap=4.0, min_share=0.75, passes=8,
                choice_sigma_space=choice)


class _Both:
    """``fill._kernel`` replaced: every pass runs the kernel and the torch reference on the same planes and pixels,
    keeps their outputs, and goes on with the kernel's."""

    def __init__(self):
        self.kernel = fill._kernel()
        assert self.kernel is not None
        self.passes = []

    def __call__(self, p, bi, yi, xi):
        mine = self.kernel(p, bi, yi, xi)
        ref = _fill_pixels(p, bi, yi, xi)
        self.passes.append((mine, ref, p.x.dtype))
        return mine


def _max(t):
    return t.max() if t.numel() else torch.zeros(())


def _check_pass(mine, ref, dt):
    est, c_new, spans, share, ok, weak = mine
    r_est, r_c, r_spans, r_share, r_ok, r_weak = ref
    for a, r in zip(mine, ref):
        assert a.shape == r.shape and a.dtype == r.dtype
    assert torch.equal(ok, r_ok) and torch.equal(weak, r_weak) and torch.equal(spans, r_spans)
    # where the two sides' masses tie exactly the summation order picks the side (a different one per path): the
    # pixels whose reference share is within round-off of 1/2; none of the others may differ
    tol = 1e-5 if dt == torch.float32 else 1e-12
    tie = (r_share - 0.5).abs() < 4 * tol
    same = ok & ~tie
    scale = 1 + r_est.abs()
    assert float(_max(((est - r_est).abs() / scale)[same])) < tol
    # the share is used where the window spans a gap only; elsewhere its 2-means split one noisy surface, where a
    # value within round-off of a threshold may land on the other side
    assert float(_max((share - r_share).abs()[ok & spans])) < 4 * tol
    assert torch.equal(c_new[same], r_c[same])
    return int((ok & tie & spans).sum())


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("kernel_size,guide,quantize,choice", [
    (7, True, False, 1.5),  # the fast model's fill
    (7, False, True, None),
    (5, True, True, None),
    (11, True, False, 1.5),
    (11, False, False, 1.5),
])
def test_every_pass_matches_the_torch_reference(monkeypatch, dtype, kernel_size, guide, quantize, choice):
    y, m, rgb = _case(kernel_size + 10 * guide + 100 * quantize, dtype, guide, quantize)
    both = _Both()
    monkeypatch.setattr(fill, "_kernel", lambda: both)
    fill_holes_sided(y, m, rgb, **_settings(kernel_size, choice))
    assert len(both.passes) >= 3  # the deep holes take several passes
    ties = sum(_check_pass(*p) for p in both.passes)
    pixels = sum(int(p[1][4].sum()) for p in both.passes)
    assert ties <= 0.01 * pixels, (ties, pixels)
    spans = sum(int(p[1][2].sum()) for p in both.passes)
    assert spans > 0  # the step is seen
    if guide:
        assert any(bool(p[1][5].any()) for p in both.passes)  # so are the weak pixels (colours no neighbour has)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("kernel_size,guide,quantize,choice", [
    (7, True, False, 1.5), (7, False, True, None), (5, True, True, 1.5), (11, True, False, None),
])
def test_fill_holes_sided_matches_the_torch_path(monkeypatch, dtype, kernel_size, guide, quantize, choice):
    y, m, rgb = _case(7 * kernel_size + guide + 3 * quantize, dtype, guide, quantize)
    kw = _settings(kernel_size, choice)
    fast = fill_holes_sided(y, m, rgb, **kw)
    monkeypatch.setattr(fill, "_kernel", lambda: None)
    ref = fill_holes_sided(y, m, rgb, **kw)
    assert torch.equal(fast.depth[m > 0], y[m > 0])  # measured pixels kept exactly
    # ties between the sides (see _check_pass) may pick the other side at a few pixels, and what is filled from them
    rtol = 1e-5 if dtype == torch.float32 else 1e-12
    close = (fast.depth - ref.depth).abs() <= rtol * (1 + ref.depth.abs())
    assert float((~close).float().mean()) <= 0.002, int((~close).sum())
    for a, r in ((fast.confident, ref.confident), (fast.gap, ref.gap)):
        assert float((a != r).float().mean()) <= 0.002
    share_close = (fast.share - ref.share).abs() <= 4 * rtol
    assert float((~share_close).float().mean()) <= 0.002
    if not quantize or guide:  # no exact ties in these: every pixel agrees
        assert bool(close.all()) and bool(share_close.all())
        assert torch.equal(fast.confident, ref.confident) and torch.equal(fast.gap, ref.gap)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_one_and_two_threads_give_the_same_fill(monkeypatch, dtype):
    from torch_depth_sr import fill_kernel

    y, m, rgb = _case(5, dtype, True, False, h=64, w=96)
    kw = _settings(7, 1.5)
    old = torch.get_num_threads()
    monkeypatch.setattr(fill_kernel, "_MIN_SHARE_PIXELS", 16)  # two shares even in the last passes
    try:
        torch.set_num_threads(1)
        one = fill_holes_sided(y, m, rgb, **kw)
        torch.set_num_threads(2)
        two = fill_holes_sided(y, m, rgb, **kw)
    finally:
        torch.set_num_threads(old)
    for a, b in zip(one, two):
        assert torch.equal(a, b)


def test_the_kernel_serves_only_without_gradient(monkeypatch):
    y, m, rgb = _case(3, torch.float64, True, False, b=1)
    calls = []
    kernel = fill._kernel()
    monkeypatch.setattr(fill, "_kernel", lambda: calls.append(1) or kernel)
    fill_holes_sided(y, m, rgb, kernel_size=7)
    assert calls
    calls.clear()
    fill_holes_sided(y.requires_grad_(), m, rgb, kernel_size=7)
    assert not calls
    fill_holes_sided(y.detach().half(), m.half(), rgb.half(), kernel_size=7)
    assert not calls


def test_one_guide_for_a_batch(monkeypatch):
    """A (1,3,H,W) guide for a batch of 2 depths: each sample reads the one guide."""
    y, m, rgb = _case(23, torch.float32, True, False)
    both = _Both()
    monkeypatch.setattr(fill, "_kernel", lambda: both)
    fill_holes_sided(y, m, rgb[:1], **_settings(7, 1.5))
    for p in both.passes:
        _check_pass(*p)


@pytest.mark.parametrize("kernel", [True, False])
def test_inputs_of_any_strides_give_the_same_fill(monkeypatch, kernel):
    """Transposed (dense, not contiguous) depth, mask and guide: the planes are made contiguous, the fill is that of
    contiguous inputs."""
    if not kernel:
        monkeypatch.setattr(fill, "_kernel", lambda: None)
    y, m, rgb = _case(29, torch.float32, True, False, h=40, w=40)
    t = (lambda a: a.transpose(-1, -2).contiguous().transpose(-1, -2))
    ref = fill_holes_sided(y, m, rgb, **_settings(7, 1.5))
    assert not t(y).is_contiguous()
    out = fill_holes_sided(t(y), t(m), t(rgb), **_settings(7, 1.5))
    for a, r in zip(out, ref):
        assert torch.equal(a, r)


@pytest.mark.parametrize("quantiles", [(0.25, 0.75), (0.4, 0.6), (0.0, 1.0)])
def test_other_quantiles_match(monkeypatch, quantiles):
    """Ranks far from the ends (0.4 of 49 values: the insertion sort) and at them (0, 1)."""
    y, m, rgb = _case(17, torch.float32, True, True)
    both = _Both()
    monkeypatch.setattr(fill, "_kernel", lambda: both)
    fill_holes_sided(y, m, rgb, **_settings(7, 1.5), quantiles=quantiles)
    assert sum(int(p[1][2].sum()) for p in both.passes) > 0
    for p in both.passes:
        _check_pass(*p)


def test_a_large_window_sorts_past_the_insertion_sort(monkeypatch):
    """A 21×21 window holds up to 441 measured values (np.sort instead of the insertion sort)."""
    y, m, rgb = _case(11, torch.float64, True, True, b=1, h=40, w=48)
    both = _Both()
    monkeypatch.setattr(fill, "_kernel", lambda: both)
    fill_holes_sided(y, m, rgb, **{**_settings(21, 1.5), "passes": 1})
    assert both.passes
    for p in both.passes:
        _check_pass(*p)


def test_planes_type_is_what_the_kernel_reads():
    assert set(_FillPlanes._fields) >= {"x", "conf", "filled", "guide_rows", "ws", "wch", "dy", "dx", "h", "w",
                                        "sigma_color", "quantiles", "gap", "min_share"}
