r"""Shrinkage (proximal) operators of the ℓ₁ terms.

* :func:`soft_threshold`, the proximal map of ``t‖·‖₁`` (anisotropic TV, paper eq. 3-7/3-8):

  .. math:: \operatorname{soft}(v, t) = \operatorname{sign}(v)\,\max(|v| - t, 0)

* :func:`group_soft_threshold`, the proximal map of ``t Σ_i ‖v_i‖₂`` over a group dimension
  (isotropic TV when the group is the 2-vector of a gradient):

  .. math:: \operatorname{gsoft}(v, t) = v \cdot \max\!\left(1 - \frac{t}{\|v\|_2}, 0\right)

Thresholds are a float or a tensor: a 1-D tensor of length ``B`` is per sample (reshaped to
``(B, 1, 1, 1)``), any other tensor must broadcast against ``v``. :class:`SoftThreshold` stores a
fixed or learnable threshold; learnable thresholds are kept positive as
``softplus(raw)`` of an unconstrained parameter.
"""
from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from .errors import DepthSRError, ShapeError

__all__ = ["SoftThreshold", "group_soft_threshold", "soft_threshold"]


def _as_threshold(t: float | torch.Tensor, v: torch.Tensor, name: str = "t") -> float | torch.Tensor:
    """Validate a threshold and shape it to broadcast against ``v`` (per-sample (B,) → (B,1,...))."""
    if isinstance(t, torch.Tensor):
        if t.ndim == 1 and v.ndim > 1 and t.shape[0] == v.shape[0] and t.shape[0] != 1:
            t = t.view((-1,) + (1,) * (v.ndim - 1))  # (B, 1, 1, 1)
        try:  # numpy's rule, the same as torch's: torch.broadcast_shapes imports sympy on its first call (0.9 s)
            np.broadcast_shapes(tuple(t.shape), tuple(v.shape))
        except ValueError:
            raise ShapeError(
                f"threshold {name} of shape {tuple(t.shape)} does not broadcast against v of shape "
                f"{tuple(v.shape)}; use a float, a 0-d tensor, a per-sample (B,) tensor with B={v.shape[0]}, "
                f"or a tensor broadcastable to v.",
                actual=tuple(t.shape), expected=f"(), ({v.shape[0]},) or broadcastable to {tuple(v.shape)}",
            ) from None
        return t.to(dtype=v.dtype) if t.is_floating_point() and t.dtype != v.dtype else t
    if isinstance(t, bool) or not isinstance(t, (int, float)):
        raise DepthSRError(f"threshold {name} must be a float or a tensor; got {type(t).__name__}.")
    if not (t >= 0) or math.isinf(t):
        raise DepthSRError(f"threshold {name} must be a finite float >= 0; got {t!r}.")
    return float(t)


def soft_threshold(v: torch.Tensor, t: float | torch.Tensor) -> torch.Tensor:
    r"""Elementwise soft threshold ``sign(v)·max(|v| − t, 0)``, the proximal map of ``t‖v‖₁``.

    Differentiable in ``v`` and in ``t`` (``∂/∂t = −sign(v)`` where ``|v| > t``, else 0).

    Args:
        v: tensor of any shape, usually ``(B, C, H, W)``.
        t: threshold ``>= 0``: a float, a 0-d tensor, a per-sample ``(B,)`` tensor, or any tensor
            broadcastable to ``v``.

    Returns:
        tensor of the shape of ``v``.

    Examples:
        >>> soft_threshold(torch.tensor([-3., -0.5, 0., 2.]), 1.0).tolist()
        [-2.0, -0.0, 0.0, 1.0]
        >>> v = torch.ones(2, 1, 1, 2)
        >>> soft_threshold(v, torch.tensor([0.25, 2.0])).flatten()
        tensor([0.7500, 0.7500, 0.0000, 0.0000])
    """
    if not isinstance(v, torch.Tensor):
        raise DepthSRError(f"v must be a torch.Tensor; got {type(v).__name__}.")
    t = _as_threshold(t, v)
    return torch.sign(v) * torch.relu(v.abs() - t)


def group_soft_threshold(v: torch.Tensor, t: float | torch.Tensor, dim: int = 1) -> torch.Tensor:
    r"""Group soft threshold ``v·max(1 − t/‖v‖₂, 0)`` with the norm taken over ``dim``.

    The proximal map of ``t Σ_i ‖v_i‖₂``; with ``v = Dx`` of shape ``(B, 2, H, W)`` and ``dim=1`` it is
    the isotropic-TV shrinkage. The norm is evaluated only where ``‖v‖ > t`` (elsewhere the output is
    exactly 0), so values and gradients are finite everywhere, including ``v = 0``.

    Args:
        v: tensor, usually ``(B, 2, H, W)``.
        t: threshold ``>= 0`` (float, 0-d, per-sample ``(B,)`` or broadcastable tensor).
        dim: the group dimension.

    Returns:
        tensor of the shape of ``v``.

    Examples:
        >>> group_soft_threshold(torch.tensor([[3.], [4.]]).view(1, 2, 1, 1), 2.5).flatten()
        tensor([1.5000, 2.0000])
    """
    if not isinstance(v, torch.Tensor):
        raise DepthSRError(f"v must be a torch.Tensor; got {type(v).__name__}.")
    if not -v.ndim <= dim < v.ndim:
        raise ShapeError(f"dim={dim} is out of range for v of shape {tuple(v.shape)}.", actual=tuple(v.shape),
                         expected=f"at least {dim + 1 if dim >= 0 else -dim} dims for dim={dim}")
    t = _as_threshold(t, v)
    sumsq = (v * v).sum(dim=dim, keepdim=True)  # (B, 1, H, W) for dim=1
    active = sumsq > t * t  # the norm is only evaluated where ‖v‖ > t
    norm = torch.sqrt(torch.where(active, sumsq, torch.ones_like(sumsq)))
    factor = torch.where(active, 1.0 - t / norm, torch.zeros_like(norm))
    return v * factor


def _inverse_softplus(t: torch.Tensor) -> torch.Tensor:
    # softplus(r) = t  <=>  r = t + log(1 - exp(-t)) = t + log(-expm1(-t))
    return t + torch.log(-torch.expm1(-t))


class SoftThreshold(nn.Module):
    r"""Soft-threshold module with a fixed or learnable threshold.

    Applies :func:`soft_threshold` (or :func:`group_soft_threshold` over ``dim=1`` when
    ``isotropic=True``) with threshold ``t · scale``.

    A learnable threshold is stored as an unconstrained parameter ``raw`` with
    ``t = softplus(raw)``, so it stays strictly positive during training. A fixed threshold is a
    buffer (moves with ``.to()``, saved in the ``state_dict``).

    Args:
        threshold: float ``>= 0`` (``> 0`` when learnable) or tensor: 0-d, or 1-D of length ``B``
            (per-sample; then inputs must have batch size ``B``).
        learnable: learn the threshold (softplus parametrisation).
        isotropic: group shrinkage over dim 1 instead of elementwise shrinkage.

    Examples:
        >>> st = SoftThreshold(0.5, learnable=True)
        >>> round(st.threshold.detach().item(), 6)
        0.5
        >>> st(torch.tensor([[[[1.0, -0.2]]]]))
        tensor([[[[0.5000, -0.0000]]]], grad_fn=<MulBackward0>)
    """

    def __init__(self, threshold: float | torch.Tensor, learnable: bool = False, isotropic: bool = False) -> None:
        super().__init__()
        t = torch.as_tensor(threshold, dtype=torch.get_default_dtype()).detach().clone()
        if not t.is_floating_point():
            t = t.to(torch.get_default_dtype())
        if t.ndim > 1:
            raise ShapeError(
                f"threshold must be a float, a 0-d tensor or a per-sample 1-D (B,) tensor; got shape {tuple(t.shape)}.",
                actual=tuple(t.shape), expected="() or (B,)",
            )
        if not torch.isfinite(t).all() or (t < 0).any():
            raise DepthSRError(f"threshold must be finite and >= 0; got {threshold!r}.")
        self.learnable = bool(learnable)
        self.isotropic = bool(isotropic)
        if self.learnable:
            if (t <= 0).any():
                raise DepthSRError(
                    f"a learnable threshold must be > 0 (it is softplus of a raw parameter); got {threshold!r}. "
                    f"Use a small positive value such as 1e-3."
                )
            self.raw = nn.Parameter(_inverse_softplus(t))
        else:
            self.register_buffer("_threshold", t)

    @property
    def threshold(self) -> torch.Tensor:
        """The current threshold ``t`` (0-d or ``(B,)``), ``softplus(raw)`` when learnable."""
        return F.softplus(self.raw) if self.learnable else self._threshold

    def forward(self, v: torch.Tensor, scale: float | torch.Tensor | None = None) -> torch.Tensor:
        """Shrink ``v`` by ``threshold · scale``.

        Args:
            v: ``(B, C, H, W)`` (``(B, 2, H, W)`` for isotropic shrinkage of a gradient).
            scale: optional float or per-sample ``(B,)`` multiplier of the threshold.

        Returns:
            tensor of the shape of ``v``.
        """
        t = self.threshold
        if t.ndim == 1 and t.shape[0] != 1 and (v.ndim < 1 or t.shape[0] != v.shape[0]):
            raise ShapeError(
                f"this SoftThreshold holds a per-sample threshold of length {t.shape[0]}, but v has shape "
                f"{tuple(v.shape)}; pass a batch of {t.shape[0]} samples or build the module with a scalar threshold.",
                actual=tuple(v.shape), expected=f"({t.shape[0]}, ...)",
            )
        if scale is not None:
            t = t * torch.as_tensor(scale, dtype=t.dtype, device=t.device)  # () or (B,)
        t = t.to(device=v.device)
        if self.isotropic:
            return group_soft_threshold(v, t, dim=1)
        return soft_threshold(v, t)

    def extra_repr(self) -> str:
        return f"learnable={self.learnable}, isotropic={self.isotropic}"
