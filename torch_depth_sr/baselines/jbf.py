"""Joint bilateral filtering and upsampling of depth guided by colour (Kopf et al. 2007): the ``jbf`` baseline.

The filters live in :mod:`torch_depth_sr.guided_filters` (the model's initial estimate uses them
too, and the core does not import the baselines); this module re-exports them, adds the module
forms and :func:`jbf_denoise`, the ``jbf`` denoising baseline of the benchmark: the masked
(mask-normalised) joint bilateral filter set up as OpenCV's ``ximgproc.jointBilateralFilter`` is
(colour sigma in grey levels of the 0–255 colour, L1 colour distance, radius ``round(1.5 σs)``),
optionally iterated with median-based outlier rejection for sensor-like inputs. See
:func:`~torch_depth_sr.guided_filters.joint_bilateral_filter` and
:func:`~torch_depth_sr.guided_filters.joint_bilateral_upsample` for the maths.
"""
from __future__ import annotations

import torch
from kornia.filters import median_blur
from torch import nn

from ..errors import DepthSRError
from ..fill import fill_holes

# the boundary helpers and the pull-push fallback are re-exported for the other baselines
from ..guided_filters import (  # noqa: F401
    _check_depth,
    _check_rgb,
    _per_sample,
    _pull_push_fill,
    _resolve_mask,
    joint_bilateral_filter,
    joint_bilateral_upsample,
)

__all__ = [
    "JointBilateralFilter",
    "JointBilateralUpsample",
    "jbf_denoise",
    "joint_bilateral_filter",
    "joint_bilateral_upsample",
]


def jbf_denoise(
    depth: torch.Tensor,
    rgb: torch.Tensor,
    mask: torch.Tensor | None = None,
    sigma_space: float = 2.0,
    sigma_color: float = 20.0,
    iterations: int = 1,
    reject: float | None = None,
    median_size: int = 5,
    color_distance_type: str = "l1",
) -> torch.Tensor:
    r"""The ``jbf`` denoising baseline: masked joint bilateral filter, optionally iterated with outlier rejection.

    One pass is :func:`joint_bilateral_filter` (normalised by the mask: holes get no weight and are
    filled) with OpenCV's conventions: ``sigma_color`` in grey levels of the 0–255 colour (the
    filter sees ``sigma_color / 255`` of the [0,1] colour), colour distance ``"l1"`` (sum of the
    channels' absolute differences, as OpenCV's 3-channel ``jointBilateralFilter``) and a window of
    radius ``round(1.5 σs)`` (OpenCV's ``d = -1``).

    ``iterations`` passes: :math:`x^0 = y`, :math:`x^{t} = \mathrm{JBF}(x^{t-1};\ m^{t})` with
    :math:`m^t` the measured pixels that are kept. Without ``reject`` every measured pixel is kept
    and the passes just smooth further (OpenCV's "iterated" JBF). With ``reject`` (grey levels of
    the depth), pass t keeps only the measured pixels whose *input* value is within ``reject`` of
    the ``median_size``×``median_size`` median of the previous estimate (for t = 1: of the input,
    holes filled by push-pull), and filters the previous estimate on those pixels: flying pixels
    and impulses become holes and are filled from their neighbours.

    Args:
        depth: (B,1,H,W) depth; missing pixels are 0 (or masked out).
        rgb: (B,3,H,W) colour in [0,1].
        mask: (B,1,H,W) 1 = measured; default ``depth > 0`` and finite.
        sigma_space: spatial sigma in pixels.
        sigma_color: colour sigma in grey levels of the 0–255 colour.
        iterations: number of passes (>= 1).
        reject: outlier threshold in depth units, or None (no rejection).
        median_size: odd window of the median the rejection compares with.
        color_distance_type: ``"l1"`` (OpenCV's) or ``"l2"``.

    Returns:
        (B,1,H,W) filtered, hole-filled depth.

    Examples:
        >>> depth = torch.full((1, 1, 24, 24), 50.0); depth[..., 5:8, 5:8] = 0.0  # a hole
        >>> depth[..., 15, 15] = 200.0  # an impulse
        >>> out = jbf_denoise(depth, torch.rand(1, 3, 24, 24), iterations=2, reject=10.0)
        >>> bool(torch.allclose(out, torch.full_like(out, 50.0)))
        True
    """
    if not isinstance(iterations, int) or iterations < 1:
        raise DepthSRError(f"iterations must be an int >= 1; got {iterations!r}.")
    if reject is not None and not reject > 0:
        raise DepthSRError(f"reject must be positive or None; got {reject!r}.")
    if not isinstance(median_size, int) or median_size < 1 or median_size % 2 == 0:
        raise DepthSRError(f"median_size must be a positive odd int; got {median_size!r}.")
    _check_depth(depth)
    m = _resolve_mask(depth, mask)
    radius = max(1, round(1.5 * float(sigma_space)))  # OpenCV's d = -1
    kernel = min(2 * radius + 1, 2 * (min(depth.shape[-2:]) - 1) + 1)  # reflect padding needs radius < size
    est = torch.where(m > 0, depth, torch.zeros_like(depth))
    keep = m
    for t in range(iterations):
        if reject is not None:
            ref = median_blur(fill_holes(est, m) if t == 0 else est, median_size)
            keep = m * ((depth - ref).abs() <= reject).to(m.dtype)
        est = joint_bilateral_filter(est, rgb, keep, kernel_size=kernel, sigma_space=float(sigma_space),
                                     sigma_color=float(sigma_color) / 255.0, color_distance_type=color_distance_type)
    return est


class JointBilateralFilter(nn.Module):
    r"""Module form of :func:`joint_bilateral_filter`; stores the settings only.

    Examples:
        >>> jbf = JointBilateralFilter(kernel_size=9, sigma_space=3.0, sigma_color=0.1)
        >>> jbf(torch.rand(2, 1, 16, 16) + 1, torch.rand(2, 3, 16, 16)).shape
        torch.Size([2, 1, 16, 16])
    """

    def __init__(
        self,
        kernel_size: int = 7,
        sigma_space: float | torch.Tensor = 2.0,
        sigma_color: float | torch.Tensor = 0.05,
        color_distance_type: str = "l2",
        fill_passes: int = 2,
    ) -> None:
        super().__init__()
        self.kernel_size = kernel_size
        self.sigma_space = sigma_space
        self.sigma_color = sigma_color
        self.color_distance_type = color_distance_type
        self.fill_passes = fill_passes

    def forward(self, depth: torch.Tensor, rgb: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        return joint_bilateral_filter(
            depth,
            rgb,
            mask,
            kernel_size=self.kernel_size,
            sigma_space=self.sigma_space,
            sigma_color=self.sigma_color,
            color_distance_type=self.color_distance_type,
            fill_passes=self.fill_passes,
        )

    def extra_repr(self) -> str:
        return (
            f"kernel_size={self.kernel_size}, sigma_space={self.sigma_space}, sigma_color={self.sigma_color}, "
            f"color_distance_type={self.color_distance_type!r}, fill_passes={self.fill_passes}"
        )


class JointBilateralUpsample(nn.Module):
    r"""Module form of :func:`joint_bilateral_upsample`; stores the settings only.

    Examples:
        >>> jbu = JointBilateralUpsample(factor=2)
        >>> jbu(torch.rand(1, 1, 8, 8) + 1, torch.rand(1, 3, 16, 16)).shape
        torch.Size([1, 1, 16, 16])
    """

    def __init__(
        self,
        factor: float | None = None,
        radius: int = 2,
        sigma_space: float | torch.Tensor = 1.0,
        sigma_color: float | torch.Tensor = 0.1,
        color_distance_type: str = "l2",
    ) -> None:
        super().__init__()
        self.factor = factor
        self.radius = radius
        self.sigma_space = sigma_space
        self.sigma_color = sigma_color
        self.color_distance_type = color_distance_type

    def forward(
        self, depth_lr: torch.Tensor, rgb_hr: torch.Tensor, mask: torch.Tensor | None = None
    ) -> torch.Tensor:
        return joint_bilateral_upsample(
            depth_lr,
            rgb_hr,
            factor=self.factor,
            mask=mask,
            radius=self.radius,
            sigma_space=self.sigma_space,
            sigma_color=self.sigma_color,
            color_distance_type=self.color_distance_type,
        )

    def extra_repr(self) -> str:
        return (
            f"factor={self.factor}, radius={self.radius}, sigma_space={self.sigma_space}, "
            f"sigma_color={self.sigma_color}, color_distance_type={self.color_distance_type!r}"
        )
