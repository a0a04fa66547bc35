r"""A learned correction of the model's output at depth edges, bounded by the measurements around each pixel.

Issue 14 ("accurate like the deep networks"). On a clean low-resolution input the unrolled model is held to its x⁰
away from depth edges (do no harm), and at the edges it cannot tell from a blend of two surfaces where, inside the
``s×s`` cell, the boundary runs: the colour image says it, but only a learned rule reads it well (DJF, DKN and
DCTNet learn it from data). :class:`EdgeRefiner` learns that rule on top of the model: a small residual CNN reads the
model's output, the bicubic interpolation of the input and the colour image, and adds a correction, which is then
clamped to the range of the low-resolution values in the 3×3 neighbourhood of the pixel's cell:

.. math::
    \hat x = \operatorname{clamp}\big(x + r\,f_\theta(\phi),\ \min_{N_3(c)} y,\ \max_{N_3(c)} y\big)

with :math:`r` the depth range of the input (so the network never sees the depth's unit) and :math:`\phi` the
features: ``x`` minus its 7×7 mean, bicubic minus ``x``, the distances of ``x`` to the clamp's two bounds, the
white-noise level of the input (:func:`~torch_depth_sr.noise.white_noise_sigma`, 0 on a clean map; a constant map,
as FFDNet gives its noise level), all divided by :math:`r/10`; ``log2(s)/4`` for the factor ``s``; and the colour
image centred on its mean. Knowing the noise level and the factor, one network serves clean and noisy input at
every factor (without them a network trained on both was 11 % worse on clean ×4 input than one trained on clean
input alone, and the latter broke down under noise). The clamp is what keeps the promise "no surface
that is not there": the output never leaves the values measured around it, whatever the network says.

The last convolution is zero-initialised: untrained, the refiner returns ``x`` (clamped). It runs only with a
colour image, and only for the task it was trained for (``refine_task``): ``"upsample"`` (``K ≠ I``, as above) or
``"denoise"`` (``K = I``). Denoising, the same network reads the same features at ``s = 1``: "bicubic" is then the
measurement itself (holes and the pixels the singular test distrusts take the model's value), the bounds are the
min/max over the 3×3 neighbourhood of those values, the noise level is the model's estimate, and the fidelity band
that follows still holds every trusted measurement. It is trained on the frozen model's outputs
(:mod:`torch_depth_sr.training.refiner`); the model's own parameters stay as they are.
"""
from __future__ import annotations

import math
from typing import Optional

import torch
import torch.nn.functional as F
from torch import nn

from .band import clamp_between
from .precision import network_autocast, uses_bfloat16
from .window_max import max_filter, min_filter

__all__ = ["EdgeRefiner", "REFINER_FEATURES"]

REFINER_FEATURES = 9
"""Input channels of the network: four depth features, the noise level, the factor and the three colour channels."""

_FEATURE_GAIN = 10.0  # features and output in units of r/10: a depth edge spans a few units, as the colour does


class EdgeRefiner(nn.Module):
    """The refiner of :mod:`torch_depth_sr.refiner`: ``layers`` hidden 3×3 convolutions of ``channels`` features.

    Args:
        channels: width of the hidden layers.
        layers: number of hidden 3×3 convolutions (after the first).
        precision: the convolutions' arithmetic (:mod:`torch_depth_sr.precision`: ``"auto"``, ``"float32"`` or
            ``"bfloat16"``).

    Examples:
        >>> ref = EdgeRefiner(channels=8, layers=1)
        >>> x, lr, rgb = torch.rand(1, 1, 16, 16), torch.rand(1, 1, 4, 4), torch.rand(1, 3, 16, 16)
        >>> lo, hi = ref.bounds(lr, 4)
        >>> bool(torch.equal(ref(x, lr, rgb), torch.minimum(torch.maximum(x, lo), hi)))  # untrained: clamp only
        True
    """

    def __init__(self, channels: int = 32, layers: int = 6, precision: str = "auto") -> None:
        super().__init__()
        self.precision = precision
        # in-place ReLUs: the same values without a new plane per layer (autograd keeps the output it needs)
        body: list[nn.Module] = [nn.Conv2d(REFINER_FEATURES, channels, 3, padding=1), nn.ReLU(inplace=True)]
        for _ in range(layers):
            body += [nn.Conv2d(channels, channels, 3, padding=1), nn.ReLU(inplace=True)]
        body.append(nn.Conv2d(channels, 1, 3, padding=1))
        nn.init.zeros_(body[-1].weight)
        nn.init.zeros_(body[-1].bias)
        self.body = nn.Sequential(*body)

    @staticmethod
    def bounds(lowres: torch.Tensor, factor: int) -> tuple[torch.Tensor, torch.Tensor]:
        """The clamp's bounds on the fine grid: min and max of ``lowres`` over the 3×3 cells around each pixel's."""
        lo = min_filter(lowres, 3)
        hi = max_filter(lowres, 3)
        return (F.interpolate(lo, scale_factor=factor, mode="nearest"),
                F.interpolate(hi, scale_factor=factor, mode="nearest"))

    def features(self, x: torch.Tensor, lowres: torch.Tensor, rgb: torch.Tensor, lo: torch.Tensor,
                 hi: torch.Tensor, unit: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
        """The network's input (B, 9, H, W); ``unit`` (B,1,1,1) is r/10, ``noise`` (B,1,1,1) in ``x``'s units."""
        bicubic = F.interpolate(lowres, size=x.shape[-2:], mode="bicubic", antialias=True, align_corners=False)
        local = x - F.avg_pool2d(x, 7, 1, 3, count_include_pad=False)
        level = noise.expand_as(x)
        depth = torch.cat([local, bicubic - x, hi - x, x - lo, level], 1) / unit
        factor = torch.full_like(x, math.log2(x.shape[-1] / lowres.shape[-1]) / 4)
        return torch.cat([depth, factor, rgb - rgb.mean((-2, -1), keepdim=True)], 1)

    def prepare(self, x: torch.Tensor, lowres: torch.Tensor, rgb: torch.Tensor,
                noise: Optional[torch.Tensor] = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(features, lo, hi, unit)`` of a whole image: what :meth:`correct` reads (training crops them)."""
        factor = x.shape[-1] // lowres.shape[-1]
        lo, hi = self.bounds(lowres, factor)
        r = lowres.amax((-2, -1), keepdim=True) - lowres.amin((-2, -1), keepdim=True)
        unit = (r / _FEATURE_GAIN).clamp_min(torch.finfo(x.dtype).eps)
        level = torch.zeros_like(unit) if noise is None else noise.to(x).reshape(-1, 1, 1, 1).expand_as(unit)
        return self.features(x, lowres, rgb.to(x.dtype), lo, hi, unit, level), lo, hi, unit

    def correct(self, x: torch.Tensor, phi: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor,
                unit: torch.Tensor) -> torch.Tensor:
        """``x`` plus the network's step (in units of ``unit``), clamped to ``[lo, hi]``."""
        # channels-last: on the CPU oneDNN's kernels for these thin layers take half the time of the default layout
        # (the same sums in another order: the step within float rounding)
        bf16 = uses_bfloat16(self.precision, self, x, phi)
        phi = phi.to(self.body[0].weight.dtype).contiguous(memory_format=torch.channels_last)
        with network_autocast(bf16, phi.device):
            step = self.body(phi)
        step = step.to(x.dtype) * unit
        return clamp_between(x + step, lo, hi)

    def forward(self, x: torch.Tensor, lowres: torch.Tensor, rgb: torch.Tensor,
                noise: Optional[torch.Tensor] = None) -> torch.Tensor:
        """``x`` (B,1,H,W) the model's output, ``lowres`` (B,1,H/s,W/s) the input with no missing value (the model
        fills its holes from ``x``), ``rgb`` (B,3,H,W) in [0, 1], ``noise`` (B,) the input's white-noise σ in
        ``x``'s units (None: 0, a clean input). Returns the refined (B,1,H,W), in ``x``'s dtype."""
        return self.correct(x, *self.prepare(x, lowres, rgb, noise))
