"""Joint bilateral filtering and upsampling of depth guided by colour (Kopf et al. 2007): the ``jbf`` baseline.

The functions live in :mod:`torch_depth_sr.guided_filters` (the model's initial estimate uses them
too, and the core does not import the baselines); this module re-exports them and adds the module
forms. See :func:`~torch_depth_sr.guided_filters.joint_bilateral_filter` and
:func:`~torch_depth_sr.guided_filters.joint_bilateral_upsample` for the maths.
"""
from __future__ import annotations

import torch
from torch import nn

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
    "joint_bilateral_filter",
    "joint_bilateral_upsample",
]


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
