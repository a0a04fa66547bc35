r"""Rolling guidance filter (Zhang et al., ECCV 2014) on depth alone: the strongest OpenCV filter on plain noise.

Iterated joint bilateral filtering of the *input* guided by the previous result:

.. math::  g^0 = x, \qquad g^{t+1} = \mathrm{JBF}(x;\ \text{guide } g^t,\ \sigma_s,\ \sigma_c),

with ``x`` the depth whose holes are filled first (push-pull, :func:`~torch_depth_sr.fill.fill_holes`).
The paper starts from a Gaussian, :math:`g^0 = G_{\sigma_s} * x`, which removes structures smaller than
σs for good; OpenCV's ``ximgproc.rollingGuidanceFilter`` starts from the input (checked: on a noisy step
its first iteration is a bilateral filter), and on depth, whose thin structures matter, that is far better
(Art, σs 5, σc 7, 3 iterations: RMSE 1.04 against 5.4 with the Gaussian start).
The bilateral step is kornia's :func:`kornia.filters.joint_bilateral_blur`; ``sigma_color`` is in depth
units. OpenCV's ``ximgproc.rollingGuidanceFilter`` is the same iteration (issue 11 quotes its numbers with
σs 5, σc 7, 3 iterations, holes Telea-inpainted).
"""
from __future__ import annotations

import torch
from kornia.filters import joint_bilateral_blur

from .._checks import check_4d, check_same_hw
from ..fill import fill_holes

__all__ = ["rolling_guidance_filter"]


def rolling_guidance_filter(depth: torch.Tensor, mask: torch.Tensor, sigma_space: float = 5.0,
                            sigma_color: float = 7.0, iterations: int = 3) -> torch.Tensor:
    """Depth-only rolling guidance filter of ``depth (B,1,H,W)``; holes (``mask == 0``) filled first.

    Examples:
        >>> y = torch.zeros(1, 1, 24, 24); y[..., 12:] = 50.0
        >>> out = rolling_guidance_filter(y + 1.0, torch.ones_like(y))
        >>> round(float(out[0, 0, 5, 3]), 1), round(float(out[0, 0, 5, 20]), 1)  # the edge survives
        (1.0, 51.0)
    """
    check_4d(depth, "depth", 1)
    check_4d(mask, "mask", 1)
    check_same_hw(depth, mask, "depth", "mask")
    if iterations < 1:
        raise ValueError(f"iterations must be >= 1; got {iterations}.")
    x = fill_holes(depth, (mask > 0).to(depth.dtype))
    radius = max(1, round(1.5 * sigma_space))  # OpenCV d = -1
    k = min(2 * radius + 1, 2 * (min(x.shape[-2:]) // 2) - 1)  # reflect padding needs pad < size
    sigma = (float(sigma_space), float(sigma_space))
    guide = x  # OpenCV starts from the input itself (a bilateral filter), not from the paper's Gaussian
    for _ in range(iterations):
        guide = joint_bilateral_blur(x, guide, (k, k), float(sigma_color), sigma, border_type="reflect")
    return guide
