"""Shape and value checks for the public boundary (kept out of inner loops)."""
from __future__ import annotations

from numbers import Integral, Real
from typing import Any, Optional, Sequence, Union

import numpy as np
import torch

from .errors import DTypeError, ParameterError, ShapeError

__all__ = ["check_4d", "check_same_hw", "check_same_shape", "check_per_sample", "check_divisible", "check_floating",
           "check_min_size", "check_noise_sigma", "check_scale_factor"]



def check_4d(x: torch.Tensor, name: str, channels: int | Sequence[int] | None = None) -> None:
    """Raise ShapeError unless ``x`` is a ``(B, C, H, W)`` tensor with an allowed ``C``."""
    if not isinstance(x, torch.Tensor):
        raise DTypeError(f"{name} must be a torch.Tensor of shape (B,C,H,W); got {type(x).__name__}.")
    if x.ndim != 4:
        raise ShapeError(f"{name} must have shape (B,C,H,W); got {tuple(x.shape)} ({x.ndim} dims).",
                         actual=tuple(x.shape), expected="(B,C,H,W)")
    if channels is not None:
        allowed = (channels,) if isinstance(channels, int) else tuple(channels)
        if x.shape[1] not in allowed:
            raise ShapeError(
                f"{name} must have {' or '.join(map(str, allowed))} channel(s) in dim 1 of (B,C,H,W); "
                f"got shape {tuple(x.shape)}.",
                actual=tuple(x.shape), expected=f"(B,{'|'.join(map(str, allowed))},H,W)",
            )


def check_same_hw(a: torch.Tensor, b: torch.Tensor, name_a: str, name_b: str,
                  hint: str = "Align or resize the colour image to the depth map first.") -> None:
    """Raise ShapeError unless ``a`` and ``b`` share batch size and spatial size (``b`` is the one reported)."""
    if a.shape[0] != b.shape[0] or a.shape[-2:] != b.shape[-2:]:
        raise ShapeError(
            f"{name_a} and {name_b} must share batch size and height/width; got {name_a} {tuple(a.shape)} "
            f"and {name_b} {tuple(b.shape)}." + (f" {hint}" if hint else ""),
            actual=tuple(b.shape), expected=f"batch {a.shape[0]} and {tuple(a.shape[-2:])} like {name_a}",
        )


def check_same_shape(x: Any, ref: Any, name: str, ref_name: str, hint: str = "") -> None:
    """Raise ShapeError unless ``x`` (tensor or array) has exactly the shape of ``ref`` (``x`` is the one reported)."""
    if tuple(x.shape) != tuple(ref.shape):
        raise ShapeError(f"{name} must have the shape of {ref_name} {tuple(ref.shape)}; got {tuple(x.shape)}."
                         + (f" {hint}" if hint else ""),
                         actual=tuple(x.shape), expected=f"{tuple(ref.shape)}, {ref_name}'s shape")


def check_per_sample(t: torch.Tensor, name: str, batch: int) -> None:
    """Raise ShapeError unless the tensor ``t`` is 0-d or 1-d with 1 or ``batch`` values (one value per sample)."""
    if t.ndim > 1 or (t.ndim == 1 and t.shape[0] not in (1, batch)):
        raise ShapeError(f"{name} must be a float, a 0-d tensor or a per-sample (B,) tensor with B={batch}; "
                         f"got a tensor of shape {tuple(t.shape)}.",
                         actual=tuple(t.shape), expected=f"(), (1,) or ({batch},)")


def check_divisible(x: torch.Tensor, name: str, s: int, who: str) -> None:
    """Raise ShapeError unless ``x``'s height and width are multiples of ``s`` (``who`` names the caller)."""
    h, w = x.shape[-2:]
    if h % s or w % s:
        raise ShapeError(f"{who} needs H and W divisible by s={s}; got {name} of shape {tuple(x.shape)}. "
                         f"Pad or crop the high-resolution grid to a multiple of {s} first.",
                         actual=tuple(x.shape), expected=f"H, W multiples of {s}")


def check_floating(x: torch.Tensor, name: str) -> None:
    """Raise DTypeError unless ``x`` is a floating tensor."""
    if not x.is_floating_point():
        raise DTypeError(f"{name} must be a floating tensor (float32/float64); got {x.dtype}.")


def check_min_size(x: torch.Tensor, name: str, min_hw: int, why: str) -> None:
    """Raise ShapeError if ``x`` is smaller than ``min_hw`` in height or width."""
    h, w = x.shape[-2:]
    if h < min_hw or w < min_hw:
        raise ShapeError(f"{name} is {h}x{w}; it must be at least {min_hw}x{min_hw} ({why}).",
                         actual=tuple(x.shape), expected=f"H, W >= {min_hw}")


_SIGMA_ALLOWED = "None (estimate it), or a finite number > 0 in depth units, or one such number per sample"
_SIGMA_ZERO_HINT = ("0 is not allowed: every weight of the model is in multiples of σ, so σ = 0 has no scale. For "
                    "noise-free input pass the quantisation step / sqrt(12) (0.29 for integer depth) or omit it.")


def check_noise_sigma(noise_sigma: Any, batch: int) -> Union[None, float, torch.Tensor]:
    """Return ``noise_sigma`` as None, a float or a 1-D tensor of 1 or ``batch`` values; refuse anything else.

    Raises:
        ParameterError: not a real number or array of them, NaN/inf, <= 0, or neither 1 nor ``batch`` values.
    """
    if noise_sigma is None:
        return None
    if isinstance(noise_sigma, Real) and not isinstance(noise_sigma, bool):
        _check_sigma_values(noise_sigma, np.array([float(noise_sigma)]))
        return float(noise_sigma)
    t = _sigma_tensor(noise_sigma)
    if t.numel() not in (1, batch):
        raise ParameterError("noise_sigma", noise_sigma, _SIGMA_ALLOWED,
                             f"Got {t.numel()} values for a batch of {batch}.")
    _check_sigma_values(noise_sigma, t.detach().cpu().double().numpy().reshape(-1))
    return t.reshape(-1)


def _sigma_tensor(noise_sigma: Any) -> torch.Tensor:
    if isinstance(noise_sigma, torch.Tensor):
        t = noise_sigma
    else:
        try:
            arr = np.asarray(noise_sigma)
        except (TypeError, ValueError):  # ragged lists
            raise ParameterError("noise_sigma", noise_sigma, _SIGMA_ALLOWED) from None
        if arr.dtype.kind not in "fiu":
            raise ParameterError("noise_sigma", noise_sigma, _SIGMA_ALLOWED)
        t = torch.from_numpy(arr.astype(np.float64))  # a native-order copy (big-endian and read-only arrays too)
    if t.dtype == torch.bool or t.is_complex():
        raise ParameterError("noise_sigma", noise_sigma, _SIGMA_ALLOWED)
    return t


def _check_sigma_values(noise_sigma: Any, values: np.ndarray) -> None:
    if not np.isfinite(values).all() or (values < 0).any():
        raise ParameterError("noise_sigma", noise_sigma, _SIGMA_ALLOWED)
    if (values == 0).any():
        raise ParameterError("noise_sigma", noise_sigma, _SIGMA_ALLOWED, _SIGMA_ZERO_HINT)


def check_scale_factor(scale_factor: Any) -> Optional[int]:
    """Return ``scale_factor`` as None or an int >= 1 (a float, even 2.0, is refused: it is not a grid factor)."""
    if scale_factor is None:
        return None
    if isinstance(scale_factor, bool) or not isinstance(scale_factor, Integral) or scale_factor < 1:
        raise ParameterError("scale_factor", scale_factor, "None (inferred from the sizes) or an int >= 1",
                             "Guided upsampling needs colour exactly s times the depth size in both dims.")
    return int(scale_factor)
