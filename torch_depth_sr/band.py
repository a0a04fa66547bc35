"""Do no harm: the one clamp behind every band of the model — the fidelity band of trusted measurements
(:mod:`torch_depth_sr.fidelity`), the JBU x⁰ around bicubic interpolation and the output hold of guided upsampling
(:mod:`torch_depth_sr.upsampling`), and the edge refiner's local range (:mod:`torch_depth_sr.refiner`)."""
from __future__ import annotations

import torch

__all__ = ["clamp_between"]


def clamp_between(x: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """``x`` held in ``[lo, hi]`` elementwise (``lo <= hi``; broadcast), differentiable in all three.

    Examples:
        >>> clamp_between(torch.tensor([0.0, 2.0, 9.0]), torch.tensor(1.0), torch.tensor([3.0, 3.0, 5.0]))
        tensor([1., 2., 5.])
    """
    return torch.minimum(torch.maximum(x, lo), hi)
