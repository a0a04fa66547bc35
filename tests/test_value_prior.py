"""The nonlocal value prior (issue 11): the matched centres' values pull x where they agree, nowhere else."""
from __future__ import annotations

import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.block_matching import BlockMatches
from torch_depth_sr.datasets.synthetic import make_scene
from torch_depth_sr.nonlocal_prior import nonlocal_value_prior


def test_weights_only_where_the_matched_values_agree():
    x = torch.tensor([[[[1.0, 2.0, 3.0, 10.0]]]])
    # pixel 0 matches pixels 1 and 2 (values 2, 3: variance 0.25), pixel 3 matches 0 and 3 (1, 10: variance 20)
    index = torch.tensor([[[[1, 1, 1, 0]], [[2, 2, 2, 3]]]])
    weight = torch.full((1, 2, 1, 4), 0.5)
    m = BlockMatches(index=index, dist=torch.zeros_like(weight), weight=weight)
    diag, target = nonlocal_value_prior(x, m, weight=10.0, max_var=1.0)
    torch.testing.assert_close(target, torch.tensor([[[[2.5, 2.5, 2.5, 5.5]]]]))
    torch.testing.assert_close(diag, torch.tensor([[[[10.0, 10.0, 10.0, 0.0]]]]))


def _value_prior(weight: float):
    """The value prior group with η₃ = ``weight`` (0 = off)."""
    return {"weight": weight} if weight > 0 else None


def test_value_prior_lowers_the_error_on_noisy_surfaces():
    s = make_scene(64, 80, seed=5)
    g = torch.Generator().manual_seed(0)
    y = (s["gt"] + 5 * torch.randn(s["gt"].shape, generator=g)).clamp_min(1)[None]
    gt, valid = s["gt"][None], s["mask"][None] > 0
    err = {w: float((DepthRestorer(value_prior=_value_prior(w))(y, s["rgb"][None]) - gt)[valid].square().mean().sqrt())
           for w in (0.0, 10.0)}
    assert err[10.0] < err[0.0], err


def test_value_prior_does_not_shift_a_noisy_slope():
    """Matched centres on one side of a pixel (image borders, slopes) bias a plain mean x̄ on a slope; x̄ taken from
    a plane fitted to the centres (``value_prior.ridge > 0``, the default) is unbiased there.

    A 16×20 noisy ramp (0→40 across 20 columns, uniform noise of std 8.7). Measured over 40 noise seeds (the bounds
    below hold all of them):

    * the mean is not shifted: |mean(out) − mean(input)| ≤ 0.94 (0.28 typical; without the prior it is exact);
    * inside the ramp (columns 4–15) the prior helps: RMSE 0.87× that without it on average (0.61–1.19×);
    * NOT at the ramp's two ends, the image border across the slope: the prior pulls the first and last columns
      towards the middle, the mean error of the first two columns minus that of the last two is 7.5 (at most 10.6)
      against 3.1 without the prior, so the whole-image RMSE is 1.16× that without it on average (up to 1.43×).
      A known limitation, pinned here (no worse than measured), not endorsed.

    With the plain mean (``value_prior.ridge=0``) the same seeds come out 1.7–2.2× worse inside and 1.6–2.1× overall,
    the ends gap up to 13.8: the inside bound fails on each of them. The centroid gate (``value_prior.offset``) changes
    nothing on this ramp.
    """
    import numpy as np

    from torch_depth_sr import restore_depth

    h, w = 16, 20
    truth = (35 + np.linspace(0, 40, w)[None]).repeat(h, 0)
    inner = slice(4, 16)
    inner_ratios = []
    for seed in range(3):
        a = (20 + 30 * np.random.default_rng(seed).random((h, w)) + np.linspace(0, 40, w)[None]).astype(np.float32)
        out = {weight: restore_depth(a, value_prior=_value_prior(weight)).astype(np.float64) for weight in (0.0, 10.0)}
        err = {weight: o - truth for weight, o in out.items()}
        assert abs(out[0.0].mean() - a.mean()) < 1e-2  # the reference: the model without the prior keeps the mean
        assert abs(out[10.0].mean() - a.mean()) < 1.5, seed  # no shift (measured: at most 0.94)
        inner_rmse = {weight: np.sqrt((e[:, inner] ** 2).mean()) for weight, e in err.items()}
        inner_ratios.append(inner_rmse[10.0] / inner_rmse[0.0])
        assert inner_ratios[-1] < 1.25, (seed, inner_rmse)
        ends = {weight: e[:, :2].mean() - e[:, -2:].mean() for weight, e in err.items()}
        assert ends[10.0] < 12.0, (seed, ends)  # the known flattening of the ends, no worse than measured
    assert np.mean(inner_ratios) < 0.95, inner_ratios  # inside the slope the prior lowers the error
