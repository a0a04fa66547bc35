"""nonlocal_gradient: α_i = Σ_m ω[m,i] grad_x[index[m,i]]."""
import itertools

import pytest
import torch

from torch_depth_sr.block_matching import BlockMatches, block_match
from torch_depth_sr.errors import ShapeError
from torch_depth_sr.nonlocal_prior import nonlocal_gradient


def _matches(b=2, h=9, w=10, dtype=torch.float64):
    g = torch.Generator().manual_seed(0)
    x = torch.rand(b, 1, h, w, generator=g, dtype=dtype)
    return block_match(x, None, None, block_size=3, search_window=5, k=4, temperature=0.2)


def test_matches_loop():
    m = _matches()
    gx = torch.randn(2, 2, 9, 10, dtype=torch.float64)
    alpha = nonlocal_gradient(gx, m)
    assert alpha.shape == gx.shape
    for b, c, i, j in itertools.product(range(2), range(2), range(9), range(10)):
        s = sum(m.weight[b, q, i, j] * gx[b, c].flatten()[m.index[b, q, i, j]] for q in range(4))
        assert torch.isclose(alpha[b, c, i, j], s)


def test_constant_gradient_is_kept():
    m = _matches()
    gx = torch.full((2, 2, 9, 10), 3.0, dtype=torch.float64)
    torch.testing.assert_close(nonlocal_gradient(gx, m), gx)


def test_gradcheck_wrt_grad_x_and_weight():
    m = _matches(b=1, h=6, w=7)
    gx = torch.randn(1, 2, 6, 7, dtype=torch.float64, requires_grad=True)
    w = m.weight.clone().requires_grad_(True)
    assert torch.autograd.gradcheck(lambda g, ww: nonlocal_gradient(g, m._replace(weight=ww)), (gx, w))


def test_shape_error():
    m = _matches()
    bad = BlockMatches(m.dist, m.index, m.weight[:, :2])
    with pytest.raises(ShapeError, match="matches.weight must have the shape of matches.index"):
        nonlocal_gradient(torch.zeros(2, 2, 9, 10, dtype=torch.float64), bad)
    with pytest.raises(ShapeError, match="must share"):
        nonlocal_gradient(torch.zeros(2, 2, 8, 10, dtype=torch.float64), m)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_kernel_gives_nonlocal_terms_alpha_bit_for_bit_and_the_torch_path_to_rounding(monkeypatch, dtype):
    """α alone (x⁰'s α⁰): the numba kernel sums as nonlocal_terms' kernel does; the torch path in the dtype."""
    from torch_depth_sr.nonlocal_prior import nonlocal_terms
    from torch_depth_sr.operators import grad

    x = torch.rand(2, 1, 23, 31, generator=torch.Generator().manual_seed(3), dtype=dtype)
    m = block_match(x, None, None, block_size=3, search_window=7, k=5)
    alpha = nonlocal_gradient(grad(x), m)
    assert alpha.dtype == dtype and torch.equal(alpha, nonlocal_terms(x, grad(x), m)[0])
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    torch.testing.assert_close(nonlocal_gradient(grad(x), m), alpha)
