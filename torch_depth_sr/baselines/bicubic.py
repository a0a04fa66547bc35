"""Bicubic upsampling of depth: the reference baseline of the upsampling tracks."""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from ..errors import DepthSRError
from .jbf import _check_depth

__all__ = ["BicubicUpsample", "bicubic_upsample"]


def bicubic_upsample(
    depth_lr: torch.Tensor,
    factor: float | None = None,
    size: tuple[int, int] | None = None,
) -> torch.Tensor:
    r"""Bicubic upsampling of a depth map (Keys 1981 cubic convolution, :math:`a=-0.75`).

    Thin wrapper over :func:`torch.nn.functional.interpolate` with ``mode="bicubic"`` and
    ``align_corners=False``: the high-res pixel :math:`p` samples the low-res grid at
    :math:`(p + 1/2)/s - 1/2` with the separable cubic kernel. No clamping (bicubic may overshoot
    at edges) and no hole handling: zeros in ``depth_lr`` are interpolated like any value.

    Args:
        depth_lr: (B,1,h,w) low-res depth.
        factor: scale factor :math:`s` (exactly one of ``factor`` / ``size``).
        size: output ``(H, W)``; when given, the mapping uses the per-axis ratio ``h/H``.

    Returns:
        (B,1,H,W) upsampled depth, same dtype and device.

    Examples:
        >>> bicubic_upsample(torch.rand(2, 1, 8, 8), factor=4).shape
        torch.Size([2, 1, 32, 32])
        >>> bicubic_upsample(torch.rand(1, 1, 8, 8), size=(30, 33)).shape
        torch.Size([1, 1, 30, 33])
    """
    _check_depth(depth_lr, "depth_lr")
    if (factor is None) == (size is None):
        raise DepthSRError(
            f"pass exactly one of factor or size; got factor={factor!r}, size={size!r}. "
            "Example: bicubic_upsample(d, factor=4) or bicubic_upsample(d, size=rgb.shape[-2:])."
        )
    if factor is not None:
        if not factor > 0:
            raise DepthSRError(f"factor must be positive; got {factor!r}.")
        size = (round(depth_lr.shape[-2] * factor), round(depth_lr.shape[-1] * factor))
    size = (int(size[0]), int(size[1]))
    if len(size) != 2 or min(size) < 1:
        raise DepthSRError(f"size must be two positive ints (H, W); got {size!r}.")
    if depth_lr.shape[0] == 0:
        return depth_lr.new_zeros(0, 1, *size)
    if factor is not None and float(factor) == round(float(factor)):
        # An integer factor maps exactly like torch's own scale_factor path.
        return F.interpolate(
            depth_lr, scale_factor=float(factor), mode="bicubic", align_corners=False, recompute_scale_factor=False
        )
    return F.interpolate(depth_lr, size=size, mode="bicubic", align_corners=False)


class BicubicUpsample(nn.Module):
    """Module form of :func:`bicubic_upsample`; stores the settings only.

    Examples:
        >>> BicubicUpsample(factor=2)(torch.rand(1, 1, 5, 5)).shape
        torch.Size([1, 1, 10, 10])
    """

    def __init__(self, factor: float | None = None, size: tuple[int, int] | None = None) -> None:
        super().__init__()
        self.factor = factor
        self.size = size

    def forward(self, depth_lr: torch.Tensor) -> torch.Tensor:
        return bicubic_upsample(depth_lr, factor=self.factor, size=self.size)

    def extra_repr(self) -> str:
        return f"factor={self.factor}, size={self.size}"
