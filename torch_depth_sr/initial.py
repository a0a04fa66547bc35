"""The initial estimate: x⁰ on the observation grid (:func:`initial_estimate`, a colour-guided fill) and on the
output grid (:func:`~torch_depth_sr.upsampling.upsample_initial` under guided upsampling), and the module that
owns their settings, :class:`Initializer`.
"""
from __future__ import annotations

from typing import Optional, Union

import torch
from torch import nn

from .config import InitConfig, RestorerConfig, UpsamplingConfig
from .fill import fill_holes
from .operators import Degradation, area_downsample
from .upsampling import upsample_initial

__all__ = ["Initializer", "initial_estimate"]


def initial_estimate(yn: torch.Tensor, observed: torch.Tensor, guide: Optional[torch.Tensor], factor: int,
                     c: InitConfig | RestorerConfig, return_fill: bool = False
                     ) -> Union[Optional[torch.Tensor], tuple[Optional[torch.Tensor], torch.Tensor, torch.Tensor]]:
    """x⁰ on the observation grid: a colour-guided normalised convolution, or push-pull without colour.

    ``c`` is the :class:`~torch_depth_sr.config.InitConfig` (or a whole :class:`RestorerConfig`, whose
    ``initial`` group is used); ``factor`` is the ratio of the guide's grid to the depth's (the guide is
    area-averaged to the depth's grid). ``c.fill``: ``"domain"`` — masked domain-transform filter
    (:func:`~torch_depth_sr.guided_filters.domain_transform_filter`, ``dt_*``); ``"jbf"`` — masked joint
    bilateral filter (:func:`~torch_depth_sr.guided_filters.joint_bilateral_filter`, ``kernel_size``,
    ``sigma_*``); ``"pushpull"`` (or no guide) — :func:`~torch_depth_sr.fill.fill_holes`.
    Holes are filled by :func:`~torch_depth_sr.fill.fill_holes_sided` (unless ``c.sided_fill`` is None:
    ``config.extra["sided_fill"]`` False, or ``init_fill == "pushpull"``): a hole next to a depth gap takes the
    values of one side. With ``return_fill`` it returns ``(estimate, confident, sided)``, both (B,1,h,w) {0,1}:
    ``confident`` = measured, or filled with a clear side; ``sided`` = a hole next to a depth gap filled from
    one side.
    """
    from .fill import fill_holes_sided
    from .guided_filters import domain_transform_filter, joint_bilateral_filter

    if isinstance(c, RestorerConfig):
        c = c.initial
    if guide is None or c.fill == "pushpull":
        est = fill_holes(yn, observed)
        g = None
    else:
        g = area_downsample(guide, factor)  # the guide on the depth's grid (a copy when factor = 1)
        if c.fill == "domain":
            est = domain_transform_filter(yn, g, observed, sigma_space=c.dt_sigma_space,
                                          sigma_color=c.dt_sigma_color, iterations=c.dt_iterations)
        elif c.fill == "jbf":
            kernel = min(c.kernel_size, 2 * min(yn.shape[-2:]) - 1)  # reflect padding needs pad < size
            kernel -= 1 - kernel % 2
            est = joint_bilateral_filter(yn, g, observed, kernel_size=kernel, sigma_space=c.sigma_space,
                                         sigma_color=c.sigma_color)
        else:
            raise ValueError(f"init_fill={c.fill!r}; allowed are 'domain', 'jbf' and 'pushpull'.")
    confident = torch.ones_like(observed)
    one_side = torch.zeros_like(observed)
    if c.sided_fill is not None and not bool((observed > 0).all()):
        ambiguous = c.sided_fill.ambiguous
        kernel = max(3, min(c.kernel_size, 2 * (min(yn.shape[-2:]) // 2) + 1))
        with torch.no_grad():
            r = fill_holes_sided(yn.detach(), observed, g, kernel_size=kernel, sigma_space=c.sigma_space,
                                 sigma_color=c.sigma_color, **c.sided_fill.fill_arguments())
        # ambiguous="mix": a hole whose side is not clear keeps the weighted mean of both (marked unconfident)
        take = (r.confident > 0) | (ambiguous != "mix") | (g is None)
        hole = observed <= 0
        est = torch.where(hole & take, r.depth.to(est.dtype), est)
        confident = torch.where(hole, r.confident, confident)
        one_side = (hole & take & (r.gap > 0)).to(observed.dtype)
    return (est, confident, one_side) if return_fill else est


class Initializer(nn.Module):
    """x⁰ by the :class:`~torch_depth_sr.config.InitConfig` ``settings`` (the colour-guided fill on the observation
    grid, which measurements it keeps) and the :class:`~torch_depth_sr.config.UpsamplingConfig` ``upsampling`` (x⁰
    on the output grid under guided upsampling)."""

    def __init__(self, settings: InitConfig, upsampling: UpsamplingConfig):
        super().__init__()
        self.settings = settings
        self.upsampling = upsampling

    @property
    def detects_singular(self) -> bool:
        """Whether Q⁰ comes from the singular test against the guided estimate (``settings.singular``)."""
        return self.settings.singular

    def guided(self, y: torch.Tensor, observed: torch.Tensor, guide: Optional[torch.Tensor],
               K: Degradation) -> tuple[torch.Tensor, torch.Tensor]:
        """The colour-guided estimate of every pixel on the observation grid and where its fill is confident, both
        (B,1,h,w) (:func:`initial_estimate`; ``guide`` on the output grid, ``K.scale`` times finer)."""
        est, confident, _ = initial_estimate(y, observed, guide, K.scale, self.settings, return_fill=True)
        return est, confident

    def observation_grid(self, y: torch.Tensor, observed: torch.Tensor, guided: torch.Tensor,
                         trusted: Optional[torch.Tensor] = None) -> torch.Tensor:
        """x⁰ on the observation grid: ``y`` where ``trusted`` (Q⁰ of the singular test) when given, else ``y`` at
        the measured pixels with ``settings.keep_observed``, the ``guided`` estimate elsewhere."""
        if trusted is not None:
            return torch.where(trusted > 0, y, guided)
        keep = self.settings.keep_observed and guided is not None
        return torch.where(observed > 0, y, guided) if keep else guided

    def forward(self, x0: torch.Tensor, observed: torch.Tensor, guide: Optional[torch.Tensor], K: Degradation,
                noise: Optional[torch.Tensor] = None) -> torch.Tensor:
        """x⁰ on the output grid from ``x0`` on the observation grid: itself when ``K`` is the identity, else
        :func:`~torch_depth_sr.upsampling.upsample_initial` (``noise (B,)``: the noise σ in the units of ``x0``)."""
        if K.is_identity:
            return x0
        return upsample_initial(x0, observed, guide, K.scale, self.upsampling, noise=noise, degradation=K)

    def extra_repr(self) -> str:
        return f"fill={self.settings.fill!r}, upsampling={self.upsampling.init!r}"
