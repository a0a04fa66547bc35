"""White-noise level of upsampling's do-no-harm band (noise.white_noise_sigma, issue 12)."""
from __future__ import annotations

import pytest
import torch

from torch_depth_sr import restore_depth
from torch_depth_sr.noise import estimate_noise_sigma, white_noise_sigma
from torch_depth_sr.upsampling import hold_to_initial


def _ripples(h: int = 160, w: int = 160) -> torch.Tensor:
    yy, xx = torch.meshgrid(torch.arange(float(h)), torch.arange(float(w)), indexing="ij")
    return (100 + 0.6 * torch.sin(1.1 * xx + 0.3 * yy) + 0.4 * torch.sin(0.4 * xx - 0.9 * yy + 1))[None, None]


def test_fine_texture_is_not_white_noise():
    """Ripples of the noise level: the second differences take them for noise, the white-noise level does not."""
    y = _ripples()
    one = torch.ones_like(y)
    assert float(estimate_noise_sigma(y, one)) > 0.1
    assert float(white_noise_sigma(y, one)) < 0.02


@pytest.mark.parametrize("sigma", [0.5, 2.0, 5.0])
def test_white_noise_is_measured(sigma):
    g = torch.Generator().manual_seed(1)
    y = _ripples() + sigma * torch.randn(1, 1, 160, 160, generator=g)
    assert abs(float(white_noise_sigma(y, torch.ones_like(y))) / sigma - 1) < 0.1


def test_holes_and_small_inputs_fall_back_to_the_second_differences():
    y = _ripples(8, 8) + torch.randn(1, 1, 8, 8, generator=torch.Generator().manual_seed(0))
    one = torch.ones_like(y)
    assert torch.equal(white_noise_sigma(y, one), estimate_noise_sigma(y, one))


def test_clean_rippled_upsampling_is_not_worse_than_bicubic():
    """Cloth1-like: fine ripples at the noise level on a slanted plane with one depth step; two colours. A guard, not
    the discriminating check (without the hold: 1.155, with it: 1.138 at edge threshold 8, 1.160 at the default 16;
    bicubic 1.415): the hold keeps the output below bicubic and costs at most 1 % where it is not needed. The real
    Cloth1 is, in
    test_do_no_harm.test_clean_middlebury_upsampling_is_not_worse_than_bicubic (0.823 before, 0.733 after, bicubic
    0.749)."""
    import torch.nn.functional as F

    from torch_depth_sr.evaluation.clean_upsampling import degrade

    gt = _ripples(128, 160) * 2 + torch.linspace(0, 30, 160)
    gt[..., 64:, :] += 20
    gt, lr, bicubic = degrade(gt, 4, noise=0.0)
    rgb = torch.full((1, 3, *gt.shape[-2:]), 0.5)
    rgb[..., 64:, :] = 0.8
    err = {}
    for band in (0.0, 3.0):  # 0: no output hold (version 1's upsample_output_band=0)
        out = restore_depth(lr, rgb, upsample_hold={"band": band} if band else None)
        err[band] = float((out - gt).square().mean().sqrt())
    ref = float((bicubic - gt).square().mean().sqrt())
    assert err[3.0] < ref and err[3.0] <= 1.01 * err[0.0], (err, ref)
