"""Singular-pixel detection."""
import pytest
import torch

from torch_depth_sr.block_matching import block_match
from torch_depth_sr.errors import DepthSRError, ShapeError
from torch_depth_sr.singular import detect_singular


def _scene(seed=0, b=1, h=40, w=48, noise=0.5):
    g = torch.Generator().manual_seed(seed)
    yy = torch.linspace(0, 1, h).view(h, 1)
    xx = torch.linspace(0, 1, w).view(1, w)
    surface = (20 + 8 * yy + 5 * xx + 3 * torch.sin(6 * xx) * yy).expand(b, 1, h, w).contiguous()
    y = surface + noise * torch.randn(surface.shape, generator=g)
    impulses = torch.rand(surface.shape, generator=g) < 0.02
    sign = torch.where(torch.rand(surface.shape, generator=g) < 0.5, -1.0, 1.0)
    y = torch.where(impulses, y + sign * 15.0, y)
    return surface, y, impulses


def test_finds_impulses_and_keeps_clean_pixels():
    x, y, imp = _scene(b=2)
    m = block_match(x, None, None, block_size=5, search_window=11, k=8)
    obs = torch.ones_like(y)
    q = detect_singular(y, x, obs, m, sigma_floor=1.0)  # floor = 2 × noise σ
    assert q.dtype == y.dtype and q.shape == y.shape
    assert (q[imp] == 0).all()  # every impulse found
    assert q[~imp].mean() > 0.95  # clean pixels kept: |n| <= 1.177·σ_floor = 2.35 σ for ~98%


def test_missing_pixels_are_zero_and_nan_is_missing():
    x, y, imp = _scene()
    obs = torch.ones_like(y)
    obs[..., 5:9, 5:9] = 0
    y = y.clone()
    y[..., 5:9, 5:9] = 0.0
    y[..., 20, 20] = float("nan")
    m = block_match(x, None, None, block_size=5, search_window=11, k=8)
    q, p = detect_singular(y, x, obs, m, sigma_floor=0.5, return_confidence=True)
    assert (q[..., 5:9, 5:9] == 0).all() and (p[..., 5:9, 5:9] == 0).all()
    assert q[..., 20, 20] == 0 and torch.isfinite(p).all()
    assert ((q == 1) == ((p >= 0.5) & (obs > 0) & torch.isfinite(y))).all()


def test_sigma_floor_protects_flat_noisy_region():
    g = torch.Generator().manual_seed(1)
    x = torch.full((1, 1, 32, 32), 10.0)
    y = x + 0.5 * torch.randn(x.shape, generator=g)
    m = block_match(x, None, None, block_size=5, search_window=11, k=8)
    q_floor = detect_singular(y, x, torch.ones_like(y), m, sigma_floor=0.5)
    q_tiny = detect_singular(y, x, torch.ones_like(y), m, sigma_floor=1e-3)
    assert q_floor.mean() > 0.6  # |n| <= 1.177 σ holds for ~76% of Gaussian noise
    assert q_tiny.mean() < 0.05  # without a floor (σ = 0 on a flat x) nearly everything is singular


def test_rounds_and_batch_independence():
    x, y, _ = _scene(b=2, seed=3)
    m = block_match(x, None, None, block_size=5, search_window=11, k=8)
    obs = torch.ones_like(y)
    q1 = detect_singular(y, x, obs, m, sigma_floor=torch.tensor([0.5, 0.7]), rounds=1)
    q3 = detect_singular(y, x, obs, m, sigma_floor=torch.tensor([0.5, 0.7]), rounds=3)
    q10 = detect_singular(y, x, obs, m, sigma_floor=torch.tensor([0.5, 0.7]), rounds=10)
    assert q1.shape == q3.shape == q10.shape
    m0 = block_match(x[:1], None, None, block_size=5, search_window=11, k=8)
    q0 = detect_singular(y[:1], x[:1], obs[:1], m0, sigma_floor=0.5, rounds=3)
    assert torch.equal(q0, q3[:1])


def test_no_gradient():
    x, y, _ = _scene()
    x = x.clone().requires_grad_(True)
    m = block_match(x, None, None, block_size=5, search_window=11, k=8)
    q = detect_singular(y, x, torch.ones_like(y), m, sigma_floor=0.5)
    assert not q.requires_grad


def test_errors():
    x, y, _ = _scene()
    m = block_match(x, None, None, block_size=5, search_window=11, k=8)
    obs = torch.ones_like(y)
    with pytest.raises(DepthSRError, match="sigma_floor must be finite and > 0"):
        detect_singular(y, x, obs, m, sigma_floor=0.0)
    with pytest.raises(DepthSRError, match="tau must be in"):
        detect_singular(y, x, obs, m, sigma_floor=0.5, tau=1.5)
    with pytest.raises(DepthSRError, match="rounds must be"):
        detect_singular(y, x, obs, m, sigma_floor=0.5, rounds=0)
    with pytest.raises(ShapeError, match="matches"):
        detect_singular(y[..., :20, :], x[..., :20, :], obs[..., :20, :], m, sigma_floor=0.5)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("threads", [1, 2])
def test_compiled_kernel_matches_torch_path(monkeypatch, dtype, threads):
    from torch_depth_sr.block_matching import _load_clib

    if _load_clib() is None:
        pytest.skip("no C compiler here: only the torch path exists")
    x, y, _ = _scene(seed=4, b=2, noise=1.0)
    x, y = x.to(dtype), y.to(dtype)
    x = x + 0.3 * (y - x)  # an estimate that still carries some of the outliers
    obs = (torch.rand(y.shape, generator=torch.Generator().manual_seed(1)) > 0.1).to(dtype)
    m = block_match(x, None, None, block_size=3, search_window=9, k=6)
    old = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        qc, pc = detect_singular(y, x, obs, m, sigma_floor=0.8, rounds=3, return_confidence=True)
        monkeypatch.setenv("TORCH_DEPTH_SR_NO_CEXT", "1")
        qt, pt = detect_singular(y, x, obs, m, sigma_floor=0.8, rounds=3, return_confidence=True)
    finally:
        torch.set_num_threads(old)
    assert 0 < float((qt == 0).sum() - (obs == 0).sum())  # the test does reject some observed pixels
    assert (qc != qt).float().mean() <= (0 if dtype == torch.float64 else 1e-3)
    torch.testing.assert_close(pc, pt, atol=1e-5, rtol=1e-4)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_subnormal_weight_sum_gives_no_nan(monkeypatch, dtype):
    """A pixel whose only trusted neighbour has a subnormal weight: 1/s overflows unless clamped.

    (Found through a NaN in the confidence map written by ``torch-depth-sr restore --confidence``.)
    """
    from torch_depth_sr.block_matching import BlockMatches

    h, w, k = 1, 3, 2
    x = torch.tensor([[[[5.0, 1.0, 2.0]]]], dtype=dtype)
    y = x.clone()
    obs = torch.tensor([[[[1.0, 0.0, 1.0]]]], dtype=dtype)  # pixel 1 unobserved: q = 0 there
    tiny = torch.finfo(dtype).tiny / 2 ** 10  # subnormal
    index = torch.stack([torch.tensor([[1, 0, 0]]), torch.tensor([[2, 2, 1]])]).view(1, k, h, w)
    weight = torch.stack([torch.tensor([[1.0, 0.5, 0.5]]), torch.tensor([[tiny, 0.5, 0.5]])]).view(1, k, h, w)
    m = BlockMatches(torch.zeros(1, k, h, w, dtype=dtype), index, weight.to(dtype))
    out = {}
    for path in ("c", "torch"):
        if path == "torch":
            monkeypatch.setenv("TORCH_DEPTH_SR_NO_CEXT", "1")
        out[path] = detect_singular(y, x, obs, m, sigma_floor=0.5, rounds=1, return_confidence=True)
    for path, (q, p) in out.items():
        assert torch.isfinite(p).all(), path
    torch.testing.assert_close(out["c"][1], out["torch"][1])
