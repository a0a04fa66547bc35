r"""Do no harm: a trusted measurement bounds the restored value at its pixel.

A measured pixel that the singular test trusts is the truth plus noise. Restoring it may move it
by about the noise, never further: where a regulariser would carry it beyond, the surface model is
wrong there (an edge it blurs, a structure it does not know), not the measurement. The band is

.. math::  \delta = c\,\sigma_{ex}, \qquad \sigma_{ex}^2 = \max(\hat\sigma^2 - q^2/12,\ 0),

with :math:`q` the quantisation step (0 for unquantised data) and :math:`\sigma_{ex}` the noise beyond
rounding. A clean map, integer or float, has no noise beyond its grid: :math:`\delta = 0` and every
trusted pixel comes back exactly as measured (the holes are still filled); under Gaussian noise
:math:`c = 4` almost never binds.
"""
from __future__ import annotations

import torch

from .band import clamp_between

__all__ = ["clamp_to_measurements", "noise_band"]

def noise_band(step: torch.Tensor, sigma: torch.Tensor, width: float) -> torch.Tensor:
    """Half-width ``(B,)`` of the band around a trusted measurement, in depth units.

    Examples:
        >>> noise_band(torch.tensor([1.0]), torch.tensor([12 ** -0.5]), 4.0)  # clean 8-bit map
        tensor([0.])
        >>> noise_band(torch.tensor([0.0]), torch.tensor([5.0]), 4.0)  # float data, σ = 5
        tensor([20.])
    """
    return width * (sigma.square() - step.square() / 12).clamp_min(0).sqrt()


def clamp_to_measurements(x: torch.Tensor, y: torch.Tensor, trusted: torch.Tensor, band: torch.Tensor) -> torch.Tensor:
    """``x`` with each trusted pixel held within ``band`` of ``y``; other pixels unchanged.

    Args:
        x: ``(B,1,H,W)`` restored depth.
        y: ``(B,1,H,W)`` measurement (anything where ``trusted`` is 0).
        trusted: ``(B,1,H,W)`` {0,1}: measured and credible.
        band: ``(B,)`` half-widths in the units of ``x``.

    Examples:
        >>> x = torch.tensor([[[[1.0, 5.0, 9.0]]]]); y = torch.tensor([[[[1.2, 2.0, 0.0]]]])
        >>> clamp_to_measurements(x, y, torch.tensor([[[[1.0, 1.0, 0.0]]]]), torch.tensor([0.5]))
        tensor([[[[1.0000, 2.5000, 9.0000]]]])
    """
    b4 = band.to(x).view(-1, 1, 1, 1)
    held = clamp_between(x, y - b4, y + b4)
    return torch.where(trusted > 0, held, x)
