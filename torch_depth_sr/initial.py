"""The state before the first layer: x⁰ on the observation grid (:func:`initial_estimate`, a colour-guided fill) and
on the output grid (:func:`~torch_depth_sr.upsampling.upsample_initial` under guided upsampling), Q⁰ and the first
matches and α⁰; and the module that owns their settings and builds it, :class:`Initializer`.
"""
from __future__ import annotations

from typing import Optional, Union

import torch
from torch import nn

from .config import InitConfig, LayerConfig, RestorerConfig, UpsamplingConfig
from .fill import fill_holes
from .nonlocal_prior import nonlocal_terms
from .operators import Degradation, area_downsample, grad
from .stages import SingularDetector
from .state import RestorationContext, RestorationState
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
    """The state before the first layer (:meth:`forward`: x⁰, Q⁰, the first matches, α⁰) by the
    :class:`~torch_depth_sr.config.InitConfig` ``settings`` (the colour-guided fill on the observation grid, which
    measurements it keeps, whether Q⁰ comes from the singular test) and the
    :class:`~torch_depth_sr.config.UpsamplingConfig` ``upsampling`` (x⁰ on the output grid under guided
    upsampling). The block matcher and the singular detector it runs are the model's, passed in."""

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

    def output_grid(self, x0: torch.Tensor, observed: torch.Tensor, guide: Optional[torch.Tensor], K: Degradation,
                    noise: Optional[torch.Tensor] = None) -> torch.Tensor:
        """x⁰ on the output grid from ``x0`` on the observation grid: itself when ``K`` is the identity, else
        :func:`~torch_depth_sr.upsampling.upsample_initial` (``noise (B,)``: the noise σ in the units of ``x0``)."""
        if K.is_identity:
            return x0
        return upsample_initial(x0, observed, guide, K.scale, self.upsampling, noise=noise, degradation=K)

    def forward(self, ctx: RestorationContext, terms: LayerConfig, singular_detector: SingularDetector,
                noise: Optional[torch.Tensor] = None) -> RestorationState:
        """The state before the first layer: x⁰, Q⁰ and the first matches and α⁰ of the observation ``ctx.y`` (in
        units of the scale, 0 where missing) under ``ctx.K``; sets ``ctx.fill_confident`` and, for denoising with
        a guided prior, ``ctx.prior``. ``terms`` says which terms the layers compute (whether x⁰ needs matches, a
        prior); matching goes through ``ctx.block_matcher``; ``noise (B,)``: the noise σ in the units of ``y``."""
        y, observed, guide, K = ctx.y, ctx.observed, ctx.rgb, ctx.K
        # colour-guided estimate on the observation grid, every pixel; holes at depth gaps filled from one side
        guided, ctx.fill_confident = self.guided(y, observed, guide, K)
        x0 = self.observation_grid(y, observed, guided)
        matches, q, conf = None, observed, observed
        # the singular test compares the estimate with the observation pixel by pixel: K = I only
        if terms.use_singular and K.is_identity and self.detects_singular and guide is not None:
            # Q⁰ from the singular-pixel test against the guided estimate, whose matches are cleaner than
            # those of the raw input; singular pixels start from the guided value instead of y.
            q, conf = singular_detector(ctx, guided, ctx.block_matcher(guided, ctx, observed))
            x0 = self.observation_grid(y, observed, guided, trusted=q)
        if not K.is_identity:  # x⁰ to the output grid
            ctx.lowres = x0  # kept for the do-no-harm hold of the output (upsampling.hold_to_initial)
            x0 = self.output_grid(x0, observed, guide, K, noise=noise)
        elif guide is not None and terms.guided_prior > 0:  # the guided estimate lives on the output grid
            ctx.prior = guided
        zeros2 = x0.new_zeros(x0.shape[0], 2, *x0.shape[-2:])
        alpha = zeros2
        if terms.use_nonlocal or (terms.use_singular and K.is_identity):  # match x⁰ for the nonlocal term
            matches = ctx.block_matcher(x0, ctx, observed)
        if terms.use_nonlocal:
            alpha, _, _ = nonlocal_terms(x0, grad(x0), matches)
        return RestorationState(x=x0, z=zeros2, w=zeros2, e=torch.zeros_like(y), alpha=alpha, q=q,
                                confidence=conf, matches=matches)

    def extra_repr(self) -> str:
        return f"fill={self.settings.fill!r}, upsampling={self.upsampling.init!r}"
