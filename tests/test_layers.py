"""One unrolled layer against the half-quadratic splitting step written out by hand (dense matrices, loops)."""
import numpy as np
import pytest
import torch

from torch_depth_sr.block_matching import BlockMatches
from torch_depth_sr.config import RestorerConfig
from torch_depth_sr.guidance import NoGuidance
from torch_depth_sr.layers import UnrolledLayer
from torch_depth_sr.observation import Observation
from torch_depth_sr.operators import Identity
from torch_depth_sr.stages import BlockMatcher
from torch_depth_sr.state import RestorationState, RunLog

H, W, K = 5, 6, 2


def _difference_matrix(h: int, w: int) -> np.ndarray:
    """D (2hw × hw): forward differences, horizontal rows first, 0 at the last column/row (Neumann)."""
    n = h * w
    d = np.zeros((2 * n, n))
    for i in range(h):
        for j in range(w):
            p = i * w + j
            if j + 1 < w:
                d[p, p], d[p, p + 1] = -1.0, 1.0
            if i + 1 < h:
                d[n + p, p], d[n + p, p + w] = -1.0, 1.0
    return d


def _soft(v: np.ndarray, t: float) -> np.ndarray:
    return np.sign(v) * np.maximum(np.abs(v) - t, 0.0)


def _hand_step(x, y, q, alpha_old, index, weight, lam, eta, gamma, mu1, mu2, use_nonlocal, use_outliers):
    """model.md Algorithm 3.1, one iteration, K = I, on flat numpy vectors."""
    n = x.size
    d = _difference_matrix(H, W)
    dx = d @ x
    z = _soft(dx, lam / mu1)
    w = _soft(dx - alpha_old, eta / mu2) if use_nonlocal else np.zeros(2 * n)
    e = q * _soft(y - x, gamma) if use_outliers else np.zeros(n)
    alpha = np.zeros(2 * n)
    if use_nonlocal:  # α_i = Σ_j ω_ij (Dx)_j over the matched block centres j of pixel i
        for p in range(n):
            for m in range(index.shape[0]):
                j = index[m, p]
                alpha[p] += weight[m, p] * dx[j]
                alpha[n + p] += weight[m, p] * dx[n + j]
    mu2_ = mu2 if use_nonlocal else 0.0
    a = np.diag(q) + (mu1 + mu2_) * d.T @ d
    rhs = q * (y - e) + mu1 * d.T @ z + (mu2_ * d.T @ (w + alpha) if use_nonlocal else 0.0)
    return np.linalg.solve(a, rhs), z, w, e, alpha


@pytest.mark.parametrize("use_nonlocal,use_outliers", [(True, True), (False, True), (True, False)])
def test_layer_is_one_hand_written_hqs_step(use_nonlocal, use_outliers):
    g = torch.Generator().manual_seed(0)
    terms = tuple(t for t, on in (("nonlocal", use_nonlocal), ("outliers", use_outliers)) if on)  # no singular test
    cfg = RestorerConfig(weights=dict(lam=0.3, eta=0.4, gamma=0.8, mu1=1.5, mu2=0.7), terms=terms, value_prior=None,
                         block_matching={"match_layers": ()}, solver=dict(fixed_iters=(), tol=1e-12, max_iter=500),
                         clean_samples=None)
    layer = UnrolledLayer(cfg, 0).double()
    y = torch.randn(1, 1, H, W, generator=g, dtype=torch.float64) * 2
    y[0, 0, 1, 2] += 9.0  # an outlier for e
    q = (torch.rand(1, 1, H, W, generator=g) > 0.2).double()  # some untrusted pixels
    x = y + 0.5 * torch.randn(1, 1, H, W, generator=g, dtype=torch.float64)
    alpha_old = 0.3 * torch.randn(1, 2, H, W, generator=g, dtype=torch.float64)
    index = torch.randint(0, H * W, (1, K, H, W), generator=g)
    weight = torch.rand(1, K, H, W, generator=g, dtype=torch.float64)
    weight = weight / weight.sum(1, keepdim=True)
    matches = BlockMatches(torch.zeros_like(weight), index, weight)
    zeros2 = torch.zeros(1, 2, H, W, dtype=torch.float64)
    state = RestorationState(x=x, z=zeros2, w=zeros2, e=torch.zeros_like(y), alpha=alpha_old, q=q, confidence=q,
                             matches=matches)
    one = torch.ones(1, dtype=torch.float64)
    obs = Observation(y=y, observed=torch.ones_like(y), rgb=None, K=Identity(), task="denoise", raw=y,
                      offset=0 * one, scale=one, sigma=one, step=0 * one, glitches=torch.zeros_like(y).bool(),
                      sigma_given=True, block_matcher=BlockMatcher(cfg.block_matching), log=RunLog(),
                      guidance=NoGuidance())
    out = layer(state, obs)

    p = {n: float(layer.value(n)) for n in layer.names}
    flat = lambda t: t[0].reshape(-1).numpy()  # noqa: E731  (C,H,W) -> channel-major vector like D's rows
    x_new, z, w, e, alpha = _hand_step(flat(x), flat(y), flat(q), flat(alpha_old), index[0].reshape(K, -1).numpy(),
                                       weight[0].reshape(K, -1).numpy(), p["lam"], p["eta"], p["gamma"], p["mu1"],
                                       p["mu2"], use_nonlocal, use_outliers)
    np.testing.assert_allclose(flat(out.z), z, atol=1e-12)
    np.testing.assert_allclose(flat(out.e), e, atol=1e-12)
    if use_nonlocal:
        np.testing.assert_allclose(flat(out.w), w, atol=1e-12)
        np.testing.assert_allclose(flat(out.alpha), alpha, atol=1e-12)
    np.testing.assert_allclose(flat(out.x), x_new, atol=1e-8)
    assert not np.allclose(x_new, flat(x), atol=1e-3)  # the step moved x: the comparison is not vacuous
