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


@pytest.mark.parametrize("backend", ["torch", "numba"])
def test_second_round_drops_a_pixel_whose_support_was_singular(backend):
    """Pixel 0's matches are pixels 1 (x = 0) and 2 (x = 10). Round 1: all trusted, μ = 5, σ = 5, y₀ = 3 passes.
    Pixel 2 (y = 10 against μ = x₁ = 0, σ = floor) fails round 1, so in round 2 pixel 0 is tested against pixel 1
    alone (μ = 0, σ = 1) and fails: Q = [1,1,0] after one round, [0,1,0] after two and more."""
    from torch_depth_sr.block_matching import BlockMatches

    if backend == "numba" and not _has_numba():
        pytest.skip("numba is not installed")
    x = torch.tensor([[[[0.0, 0.0, 10.0]]]])
    y = torch.tensor([[[[3.0, 0.0, 10.0]]]])
    index = torch.tensor([[1, 1, 1], [2, 1, 1]]).view(1, 2, 1, 3)
    m = BlockMatches(torch.zeros(1, 2, 1, 3), index, torch.full((1, 2, 1, 3), 0.5))
    q = {r: detect_singular(y, x, torch.ones_like(y), m, sigma_floor=1.0, rounds=r, backend=backend).flatten().tolist()
         for r in (1, 2, 3)}
    assert q == {1: [1.0, 1.0, 0.0], 2: [0.0, 1.0, 0.0], 3: [0.0, 1.0, 0.0]}


def test_batch_independence():
    x, y, _ = _scene(b=2, seed=3)
    m = block_match(x, None, None, block_size=5, search_window=11, k=8)
    obs = torch.ones_like(y)
    q3 = detect_singular(y, x, obs, m, sigma_floor=torch.tensor([0.5, 0.7]), rounds=3)
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
    with pytest.raises(DepthSRError, match="reach must be"):
        detect_singular(y, x, obs, m, sigma_floor=0.5, region=obs > 0)
    with pytest.raises(ShapeError, match="matches"):
        detect_singular(y[..., :20, :], x[..., :20, :], obs[..., :20, :], m, sigma_floor=0.5)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("threads", [1, 2])
def test_numba_kernel_matches_torch_path(dtype, threads):
    pytest.importorskip("numba")
    x, y, _ = _scene(seed=4, b=2, noise=1.0)
    x, y = x.to(dtype), y.to(dtype)
    x = x + 0.3 * (y - x)  # an estimate that still carries some of the outliers
    obs = (torch.rand(y.shape, generator=torch.Generator().manual_seed(1)) > 0.1).to(dtype)
    m = block_match(x, None, None, block_size=3, search_window=9, k=6)
    old = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        qn, pn = detect_singular(y, x, obs, m, sigma_floor=0.8, rounds=3, return_confidence=True, backend="numba")
        qt, pt = detect_singular(y, x, obs, m, sigma_floor=0.8, rounds=3, return_confidence=True, backend="torch")
    finally:
        torch.set_num_threads(old)
    assert qn.dtype == pn.dtype == dtype
    assert 0 < float((qt == 0).sum() - (obs == 0).sum())  # the test does reject some observed pixels
    assert (qn != qt).float().mean() <= (0 if dtype == torch.float64 else 1e-3)
    torch.testing.assert_close(pn, pt, atol=1e-5, rtol=1e-4)


@pytest.mark.parametrize("threads", [1, 2])
def test_a_region_gets_the_q_and_p_of_every_pixel_computed(threads):
    """``region``: the numba kernel computes each round only where the region's result reads it (the region, and the
    matched centres of a later round's pixels); at the region's pixels Q and P are those of the whole test, bit for
    bit, while pixels far from it are left out (their Q stays Q⁰ = measured, their P 0)."""
    pytest.importorskip("numba")
    x, y, _ = _scene(seed=4, b=2, noise=1.0)
    x = x + 0.3 * (y - x)
    obs = (torch.rand(y.shape, generator=torch.Generator().manual_seed(1)) > 0.1).float()
    m = block_match(x, None, None, block_size=3, search_window=9, k=6)
    region = torch.zeros_like(y, dtype=torch.bool)
    region[0, 0, 5:12, 30:44] = True
    region[1, 0, 20:26, 3:9] = True
    old = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        q_all, p_all = detect_singular(y, x, obs, m, sigma_floor=0.8, rounds=3, return_confidence=True,
                                       backend="numba")
        q, p = detect_singular(y, x, obs, m, sigma_floor=0.8, rounds=3, return_confidence=True, region=region,
                               reach=4, backend="numba")
    finally:
        torch.set_num_threads(old)
    assert torch.equal(q[region], q_all[region]) and torch.equal(p[region], p_all[region])
    assert (q_all[region] == 0).any() and (q_all[region] != obs[region]).any()  # the region holds rejected pixels
    far = torch.ones_like(region)
    far[0, 0, 0:12 + 8, 30 - 8:44 + 8] = False  # beyond 2 reaches of the region: no round computed
    far[1, 0, 20 - 8:26 + 8, 0:9 + 8] = False
    assert torch.equal(q[far], obs[far]) and not p[far].any()
    assert (q_all[far] != obs[far]).any()  # the whole test does reject pixels there


def test_later_rounds_change_q():
    """Pixels rejected in round 1 leave the statistics, so round 2 trusts or rejects others: Q differs."""
    x, y, _ = _scene(seed=4, b=1, noise=1.0)
    x = x + 0.5 * (y - x)  # outliers still in the estimate: they widen σ around them in round 1
    m = block_match(x, None, None, block_size=3, search_window=9, k=6)
    obs = torch.ones_like(y)
    for backend in ("numba", "torch") if _has_numba() else ("torch",):
        q1 = detect_singular(y, x, obs, m, sigma_floor=0.8, rounds=1, backend=backend)
        q3 = detect_singular(y, x, obs, m, sigma_floor=0.8, rounds=3, backend=backend)
        assert (q1 != q3).any(), backend


def test_stopping_early_at_a_fixed_point_changes_nothing():
    """Once a round changes no Q, later rounds change nothing: the early exit (CPU) gives the result of all rounds."""
    from torch_depth_sr.singular import _as_batch, _singular_torch

    x, y, _ = _scene(seed=1, b=1, noise=1.0)  # Q changes in rounds 2 and 3, then stays (some inputs oscillate)
    m = block_match(x, None, None, block_size=3, search_window=9, k=6)
    obs = torch.ones_like(y) > 0
    floor = _as_batch(0.8, "sigma_floor", 1, y)
    q_all, p_all = _singular_torch(y, obs, x, m, floor, 0.5, rounds=12, early_exit=False)
    q_one = _singular_torch(y, obs, x, m, floor, 0.5, rounds=1, early_exit=False)[0]
    q_11 = _singular_torch(y, obs, x, m, floor, 0.5, rounds=11, early_exit=False)[0]
    assert not torch.equal(q_one, q_all) and torch.equal(q_11, q_all)  # Q changes, then reaches a fixed point
    for backend in ("numba", "torch") if _has_numba() else ("torch",):
        q, p = detect_singular(y, x, obs.float(), m, sigma_floor=0.8, rounds=12, return_confidence=True,
                               backend=backend)
        assert torch.equal(q, q_all), backend
        torch.testing.assert_close(p, p_all, atol=1e-6, rtol=1e-5)


def test_backend_errors():
    x, y, _ = _scene()
    m = block_match(x, None, None, block_size=5, search_window=11, k=8)
    with pytest.raises(DepthSRError, match="backend must be"):
        detect_singular(y, x, torch.ones_like(y), m, sigma_floor=0.5, backend="c")


def test_inputs_not_modified():
    x, y, _ = _scene(b=2)
    obs = (torch.rand(y.shape, generator=torch.Generator().manual_seed(3)) > 0.1).float()
    m = block_match(x, None, None, block_size=3, search_window=9, k=6)
    before = [t.clone() for t in (y, x, obs, m.index, m.weight)]
    for backend in ("numba", "torch") if _has_numba() else ("torch",):
        detect_singular(y, x, obs, m, sigma_floor=0.8, backend=backend)
        for a, b in zip(before, (y, x, obs, m.index, m.weight)):
            assert torch.equal(a, b)


def _has_numba():
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_subnormal_weight_sum_gives_no_nan(dtype):
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
    if not _has_numba():
        pytest.skip("numba is not installed: there is no second path to compare the torch path with")
    out = {path: detect_singular(y, x, obs, m, sigma_floor=0.5, rounds=1, return_confidence=True, backend=path)
           for path in ("numba", "torch")}
    for path, (q, p) in out.items():
        assert torch.isfinite(p).all(), path
    torch.testing.assert_close(out["numba"][1], out["torch"][1])


def test_line_support_keeps_thin_structures_and_rejects_flying_and_impulse_pixels():
    from torch_depth_sr.singular import line_support

    y = torch.full((1, 1, 9, 12), 100.0)
    y[..., 5:] = 40.0  # an edge between two surfaces at column 5
    y[..., :, 2] = 10.0  # a one-pixel gap showing the background, from the top to the bottom border
    y[..., 3, 4], y[..., 4, 4] = 70.0, 71.0  # two agreeing flying pixels between the sides of the edge
    y[..., 6, 8] = 250.0  # an impulse
    y[..., 2, 10] = 60.0  # a lone pixel inside a surface: not a chain
    obs = torch.ones_like(y)
    got = line_support(y, obs, 2.0)[0, 0]
    assert bool(got[:, 2].all())  # the whole gap, both ends included
    assert not bool(got[3, 4]) and not bool(got[4, 4]) and not bool(got[6, 8]) and not bool(got[2, 10])
    assert not bool(got[:, [0, 1, 3]].any()) and not bool(got[:, 5:].any())  # wide surfaces: not lines
    obs[..., 4, 2] = 0  # a missing pixel breaks the chain but both halves are still lines
    got = line_support(y, obs, 2.0)[0, 0]
    assert bool(got[:4, 2].all()) and bool(got[5:, 2].all()) and not bool(got[4, 2])


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_support_kernel_matches_torch_path(dtype, monkeypatch):
    """supported_or_line's numba kernel against its tensor operations (TORCH_DEPTH_SR_NO_NUMBA), bit for bit, on
    surfaces of a few levels (many neighbours exactly at the tolerance), noise, holes, NaN, per-sample tolerances and
    images down to one row or column."""
    from torch_depth_sr import singular

    g = torch.Generator().manual_seed(0)
    cases = []
    for trial in range(24):
        h, w = torch.randint(2, 30, (2,), generator=g).tolist()
        h, w = (1, 9) if trial == 0 else (7, 1) if trial == 1 else (h, w)
        y = torch.randint(0, 6, (2, 1, h, w), generator=g).to(dtype) * 1.5
        y = y + (trial % 2) * 0.2 * torch.randn(2, 1, h, w, generator=g, dtype=dtype)
        y[0, 0, 0, 0] = float("nan")
        obs = (torch.rand(2, 1, h, w, generator=g) > 0.2).to(dtype)
        tol = torch.rand(2, generator=g, dtype=dtype) + 0.5 if trial % 3 else 1.5
        cases.append((y, obs, tol, 1 + trial % 5))
    from torch_depth_sr.native import cpu_kernel

    assert cpu_kernel("singular_kernel", "support_cpu") is not None  # the kernel ran, not the torch path
    got = [singular.supported_or_line(*c) for c in cases]
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    for c, a in zip(cases, got):
        assert torch.equal(a, singular.supported_or_line(*c))
