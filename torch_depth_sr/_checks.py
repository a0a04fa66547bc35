"""Shape and value checks for the public boundary (kept out of inner loops)."""
from __future__ import annotations

from typing import Sequence

import torch

from .errors import DTypeError, ShapeError


def check_4d(x: torch.Tensor, name: str, channels: int | Sequence[int] | None = None) -> None:
    """Raise ShapeError unless ``x`` is a ``(B, C, H, W)`` tensor with an allowed ``C``."""
    if not isinstance(x, torch.Tensor):
        raise DTypeError(f"{name} must be a torch.Tensor of shape (B,C,H,W); got {type(x).__name__}.")
    if x.ndim != 4:
        raise ShapeError(f"{name} must have shape (B,C,H,W); got {tuple(x.shape)} ({x.ndim} dims).")
    if channels is not None:
        allowed = (channels,) if isinstance(channels, int) else tuple(channels)
        if x.shape[1] not in allowed:
            raise ShapeError(
                f"{name} must have {' or '.join(map(str, allowed))} channel(s) in dim 1 of (B,C,H,W); "
                f"got shape {tuple(x.shape)}."
            )


def check_same_hw(a: torch.Tensor, b: torch.Tensor, name_a: str, name_b: str) -> None:
    """Raise ShapeError unless ``a`` and ``b`` share batch size and spatial size."""
    if a.shape[0] != b.shape[0] or a.shape[-2:] != b.shape[-2:]:
        raise ShapeError(
            f"{name_a} and {name_b} must share batch size and height/width; got {name_a} {tuple(a.shape)} "
            f"and {name_b} {tuple(b.shape)}. Align or resize the colour image to the depth map first."
        )


def check_floating(x: torch.Tensor, name: str) -> None:
    """Raise DTypeError unless ``x`` is a floating tensor."""
    if not x.is_floating_point():
        raise DTypeError(f"{name} must be a floating tensor (float32/float64); got {x.dtype}.")


def check_min_size(x: torch.Tensor, name: str, min_hw: int, why: str) -> None:
    """Raise ShapeError if ``x`` is smaller than ``min_hw`` in height or width."""
    h, w = x.shape[-2:]
    if h < min_hw or w < min_hw:
        raise ShapeError(f"{name} is {h}x{w}; it must be at least {min_hw}x{min_hw} ({why}).")
