r"""Initial hole fill :math:`x^0` by push-pull normalised convolution.

Missing pixels get the mask-weighted average of a coarser level of a Gaussian-like
pyramid (2×2 box "push"), pulled back up with bilinear interpolation. Measured pixels
are kept exactly. It is a fast, smooth, parameter-free fill; the restoration model
then refines the filled values with its regularisers.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

from ._checks import check_4d, check_same_hw


def fill_holes(depth: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    r"""Fill the pixels where ``mask == 0`` by push-pull normalised convolution.

    .. math::
        x^0_i = y_i \ \text{if } m_i = 1, \qquad
        x^0_i = \uparrow\!\Big(\frac{\downarrow(m\,y)}{\downarrow m}\Big)_i \ \text{otherwise},

    applied recursively over a pyramid until every pixel has support.

    Args:
        depth: ``(B,1,H,W)`` depth; values where ``mask == 0`` are ignored.
        mask: ``(B,1,H,W)`` with 1 = measured, 0 = missing. Each sample needs at least one measured pixel.

    Returns:
        ``(B,1,H,W)`` filled depth (a new tensor), equal to ``depth`` where ``mask == 1``.

    Examples:
        >>> y = torch.tensor([[[[1., 0., 3.]]]]); m = (y > 0).float()
        >>> fill_holes(y, m)
        tensor([[[[1., 2., 3.]]]])
    """
    check_4d(depth, "depth", 1)
    check_4d(mask, "mask", 1)
    check_same_hw(depth, mask, "depth", "mask")
    mask = mask.to(depth.dtype)
    values = torch.where(mask > 0, depth, torch.zeros_like(depth))
    return _push_pull(values * mask, mask)


def _push_pull(weighted: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """Recursive push-pull on (sum of weighted values, sum of weights)."""
    h, w = weighted.shape[-2:]
    estimate = weighted / weight.clamp_min(1e-12)
    if bool((weight > 0).all()) or (h <= 1 and w <= 1):
        return estimate
    # push: 2x2 sums (ceil mode keeps the last odd row/column)
    coarse_weighted = F.avg_pool2d(weighted, 2, ceil_mode=True) * 4  # (B,1,ceil(H/2),ceil(W/2))
    coarse_weight = F.avg_pool2d(weight, 2, ceil_mode=True) * 4
    coarse = _push_pull(coarse_weighted, coarse_weight)
    # pull: bilinear back to this level; keep the pixels that have support here
    up = F.interpolate(coarse, size=(h, w), mode="bilinear", align_corners=False)
    has = (weight > 0).to(estimate.dtype)
    return has * estimate + (1 - has) * up
