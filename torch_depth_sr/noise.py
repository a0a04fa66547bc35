r"""Noise level estimation and the depth scale policy.

**Scale policy.** The model never sees raw units. Each sample is normalised as

.. math::  y_n = (y - m) / \hat\sigma,

with :math:`m` the median of the measured depth and :math:`\hat\sigma` the noise level
estimated on measured pixels. Every threshold and weight of the model (λ, η, γ, the
singular-pixel σ floor, block-matching temperature) is therefore expressed in multiples
of the noise level, and one parameter set serves disparity in pixels, millimetres and
metres alike: restoring ``1000·y`` gives exactly ``1000·`` the result.

The noise level is the robust (MAD) standard deviation of second differences
:math:`y_{i-1} - 2y_i + y_{i+1}` over triplets of measured pixels in both directions;
second differences cancel planar slopes, and the median ignores depth edges,
flying pixels and impulses. For a Gaussian noise of std σ, the second difference has
std :math:`\sqrt 6\,σ`.
"""
from __future__ import annotations

import torch

_MAD_TO_STD = 1.4826


def estimate_noise_sigma(depth: torch.Tensor, observed: torch.Tensor) -> torch.Tensor:
    """Estimate the per-sample noise std of ``depth (B,1,H,W)`` on ``observed`` pixels.

    Returns ``(B,)`` in the units of ``depth``. Samples with too few measured triplets
    (fewer than 16) or a perfectly smooth surface get 0; callers floor it (see :func:`depth_scale`).

    Examples:
        >>> g = torch.Generator().manual_seed(0)
        >>> y = 100 + 5 * torch.randn(1, 1, 200, 200, generator=g)
        >>> round(float(estimate_noise_sigma(y, torch.ones_like(y))), 1)
        5.0
    """
    b = depth.shape[0]
    out = depth.new_zeros(b)
    d = depth.detach()
    m = observed > 0
    dh = d[..., :, :-2] - 2 * d[..., :, 1:-1] + d[..., :, 2:]
    mh = m[..., :, :-2] & m[..., :, 1:-1] & m[..., :, 2:]
    dv = d[..., :-2, :] - 2 * d[..., 1:-1, :] + d[..., 2:, :]
    mv = m[..., :-2, :] & m[..., 1:-1, :] & m[..., 2:, :]
    for i in range(b):
        vals = torch.cat([dh[i][mh[i]], dv[i][mv[i]]]).abs()
        if vals.numel() >= 16:
            out[i] = _MAD_TO_STD * vals.median() / 6**0.5
    return out


def depth_scale(depth: torch.Tensor, observed: torch.Tensor, noise_sigma=None, relative_floor: float = 1e-3):
    """Return ``(offset (B,), scale (B,), sigma (B,))`` of the scale policy.

    ``scale = max(sigma, relative_floor · (p99 − p1 of measured depth), 1e-6 · |offset|)``:
    the floors only matter for noise-free or constant inputs, and all terms are
    proportional to the depth unit, so the policy stays scale-equivariant.
    ``noise_sigma`` (float or ``(B,)``, in depth units) overrides the estimate.
    """
    b = depth.shape[0]
    offset = depth.new_zeros(b)
    spread = depth.new_zeros(b)
    for i in range(b):
        vals = depth[i][observed[i] > 0].detach()
        offset[i] = vals.median()
        if vals.numel() > 1:
            q = torch.quantile(vals.float() if vals.numel() < 16_000_000 else vals[:: max(1, vals.numel() // 1_000_000)].float(),
                               torch.tensor([0.01, 0.99], device=vals.device)).to(depth.dtype)
            spread[i] = q[1] - q[0]
    if noise_sigma is None:
        sigma = estimate_noise_sigma(depth, observed)
    else:
        sigma = torch.as_tensor(noise_sigma, dtype=depth.dtype, device=depth.device).expand(b).clone()
    scale = torch.maximum(sigma, relative_floor * spread)
    scale = torch.maximum(scale, 1e-6 * offset.abs())
    scale = scale.clamp_min(torch.finfo(depth.dtype).tiny)
    return offset, scale, sigma
