"""The state before the first layer, one module per task: :class:`DenoiseInit` (x⁰ on the observation grid,
:func:`initial_estimate`, a colour-guided fill; Q⁰; the guided prior's target) and :class:`UpsampleInit` (x⁰ filled
on the observation grid and carried to the output grid, :func:`~torch_depth_sr.upsampling.bounded_upsample`). Both
match x⁰ and compute α⁰ for the layers, and return what they computed that later stages read
(:class:`InitialEstimate`)."""
from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple, Optional, Union

import torch
from torch import nn

from .config import InitConfig, RestorerConfig, SidedFill, UpsamplingConfig
from .fill import fill_holes, fill_holes_sided
from .guided_filters import domain_transform_filter, joint_bilateral_filter
from .native import host_path
from .nonlocal_prior import nonlocal_gradient
from .observation import Observation
from .operators import area_downsample, grad
from .stages import SingularDetector
from .state import RestorationState
from .upsampling import UpsamplingReference, bounded_upsample, upsampling_reference

__all__ = ["DenoiseInit", "InitialEstimate", "UpsampleInit", "initial_estimate", "initial_stages"]


def initial_estimate(yn: torch.Tensor, observed: torch.Tensor, guide: Optional[torch.Tensor], factor: int,
                     c: InitConfig, sided_fill: Optional[SidedFill] = None, return_fill: bool = False
                     ) -> Union[Optional[torch.Tensor], tuple[Optional[torch.Tensor], torch.Tensor, torch.Tensor]]:
    """x⁰ on the observation grid: a colour-guided normalised convolution, or push-pull without colour.

    ``c`` is the :class:`~torch_depth_sr.config.InitConfig`; ``factor`` is the ratio of the guide's grid to the depth's (the guide is
    area-averaged to the depth's grid). ``c.fill``: ``"domain"`` — masked domain-transform filter
    (:func:`~torch_depth_sr.guided_filters.domain_transform_filter`, ``dt_*``); ``"jbf"`` — masked joint
    bilateral filter (:func:`~torch_depth_sr.guided_filters.joint_bilateral_filter`, ``kernel_size``,
    ``sigma_*``); ``"pushpull"`` (or no guide) — :func:`~torch_depth_sr.fill.fill_holes`.
    Holes are filled by :func:`~torch_depth_sr.fill.fill_holes_sided` when ``sided_fill`` is given: a hole next to
    a depth gap takes the values of one side. With ``return_fill`` it returns ``(estimate, confident, sided)``, both (B,1,h,w) {0,1}:
    ``confident`` = measured, or filled with a clear side; ``sided`` = a hole next to a depth gap filled from
    one side.
    """
    # the filter of the holes: by c.fill, push-pull without a colour image
    est, g = _FILLS["pushpull" if guide is None else c.fill](yn, observed, guide, factor, c)
    confident = torch.ones_like(observed)
    one_side = torch.zeros_like(observed)
    # the sided fill changes nothing without holes: the CPU skips it then, other devices run it (no host wait)
    if sided_fill is not None and (not host_path(observed.device) or not bool((observed > 0).all())):
        ambiguous = sided_fill.ambiguous
        kernel = max(3, min(c.kernel_size, 2 * (min(yn.shape[-2:]) // 2) + 1))
        with torch.no_grad():
            r = fill_holes_sided(yn.detach(), observed, g, kernel_size=kernel, sigma_space=c.sigma_space,
                                 sigma_color=c.sigma_color, **sided_fill.fill_arguments())
        # ambiguous="mix": a hole whose side is not clear keeps the weighted mean of both (marked unconfident)
        take = (r.confident > 0) | (ambiguous != "mix") | (g is None)
        hole = observed <= 0
        est = torch.where(hole & take, r.depth.to(est.dtype), est)
        confident = torch.where(hole, r.confident, confident)
        one_side = (hole & take & (r.gap > 0)).to(observed.dtype)
    return (est, confident, one_side) if return_fill else est


def _push_pull(yn: torch.Tensor, observed: torch.Tensor, guide: Optional[torch.Tensor], factor: int,
               c: InitConfig) -> tuple[torch.Tensor, None]:
    return fill_holes(yn, observed), None


def _domain_transform(yn: torch.Tensor, observed: torch.Tensor, guide: torch.Tensor, factor: int,
                      c: InitConfig) -> tuple[torch.Tensor, torch.Tensor]:
    g = area_downsample(guide, factor)  # the guide on the depth's grid (a copy when factor = 1)
    return domain_transform_filter(yn, g, observed, sigma_space=c.dt_sigma_space, sigma_color=c.dt_sigma_color,
                                   iterations=c.dt_iterations), g


def _joint_bilateral(yn: torch.Tensor, observed: torch.Tensor, guide: torch.Tensor, factor: int,
                     c: InitConfig) -> tuple[torch.Tensor, torch.Tensor]:
    g = area_downsample(guide, factor)
    kernel = min(c.kernel_size, 2 * min(yn.shape[-2:]) - 1)  # reflect padding needs pad < size
    kernel -= 1 - kernel % 2
    return joint_bilateral_filter(yn, g, observed, kernel_size=kernel, sigma_space=c.sigma_space,
                                  sigma_color=c.sigma_color), g


_FILLS = {"pushpull": _push_pull, "domain": _domain_transform, "jbf": _joint_bilateral}
"""x⁰'s fill of the holes per ``InitConfig.fill``: ``(estimate, guide on the depth's grid or None)``."""


class InitialEstimate(NamedTuple):
    """What the initial stage returns: the state before the first layer, and what later stages read."""

    state: RestorationState
    fill_confident: torch.Tensor  # (B,1,h,w) {0,1}: measured, or a hole filled from a clear side (fill="trusted")
    prior: Optional[torch.Tensor] = None  # (B,1,H,W) the guided prior's target (denoising with a guide)
    supported: Optional[torch.Tensor] = None  # (B,1,h,w) pixels every singular test trusts (denoising)
    reference: Optional[UpsamplingReference] = None  # what x⁰ was upsampled from (the output hold rebuilds it)


class _Initial(nn.Module):
    """The colour-guided estimate on the observation grid and x⁰ there, by ``settings``
    (:class:`~torch_depth_sr.config.InitConfig`) and ``sided_fill``; whether x⁰ is matched (for the nonlocal term or
    the singular test) and α⁰ computed (``nonlocal_``)."""

    def __init__(self, settings: InitConfig, sided_fill: Optional[SidedFill], matches: bool, nonlocal_: bool):
        super().__init__()
        self.settings, self.sided_fill = settings, sided_fill
        self.matches, self.nonlocal_ = matches, nonlocal_
        self._keep = _keep_measured if settings.keep_observed else _guided_only
        self._match = _match if matches else _no_matches
        self._alpha = _alpha if nonlocal_ else _no_alpha

    def guided(self, obs: Observation) -> tuple[torch.Tensor, torch.Tensor]:
        """The colour-guided estimate of every pixel on the observation grid and where its fill is confident, both
        (B,1,h,w) (:func:`initial_estimate`)."""
        est, confident, _ = initial_estimate(obs.y, obs.observed, obs.rgb, obs.K.scale, self.settings,
                                             self.sided_fill, return_fill=True)
        return est, confident

    def observation_grid(self, obs: Observation, guided: torch.Tensor) -> torch.Tensor:
        """x⁰ on the observation grid: ``y`` at the measured pixels with ``settings.keep_observed``, the ``guided``
        estimate elsewhere."""
        return self._keep(obs, guided)

    def start(self, x0: torch.Tensor, obs: Observation, q: torch.Tensor, conf: torch.Tensor,
              clean: Optional[torch.Tensor]) -> RestorationState:
        """The state at x⁰: its matches (untrusted = unmeasured pixels masked) and α⁰ when the layers need them."""
        zeros2 = x0.new_zeros(x0.shape[0], 2, *x0.shape[-2:])
        matches = self._match(x0, obs)
        return RestorationState(x=x0, z=zeros2, w=zeros2, e=torch.zeros_like(obs.y),
                                alpha=self._alpha(x0, matches, zeros2), q=q, confidence=conf, matches=matches,
                                clean=clean)

    def extra_repr(self) -> str:
        return f"fill={self.settings.fill!r}, sided_fill={self.sided_fill is not None}"


class DenoiseInit(_Initial):
    """x⁰ = the measurement with its holes filled by the colour-guided estimate; Q⁰ = measured, or from the
    singular test against the guided estimate (``settings.singular``, with a ``singular`` test in the model); the
    guided estimate is also the guided prior's target (``guided_prior``)."""

    def __init__(self, settings: InitConfig, sided_fill: Optional[SidedFill], singular: Optional[SingularDetector],
                 guided_prior: bool, nonlocal_: bool):
        super().__init__(settings, sided_fill, matches=nonlocal_ or singular is not None, nonlocal_=nonlocal_)
        self.singular = singular  # the model's detector (not a copy): Q⁰ and the supported pixels
        self.guided_prior = guided_prior
        self._supported = _no_support if singular is None else _support
        self._tested = _tested if singular is not None and settings.singular else _measured
        self._prior = _guided_estimate if guided_prior else _no_prior

    def forward(self, obs: Observation) -> InitialEstimate:
        guided, confident = self.guided(obs)  # holes at depth gaps filled from one side
        supported = self._supported(self, obs)
        x0, q, conf, clean = self._tested(self, replace(obs, supported=supported), guided)
        return InitialEstimate(self.start(x0, obs, q, conf, clean), confident, prior=self._prior(guided),
                               supported=supported)


class UpsampleInit(_Initial):
    """x⁰ filled on the observation grid, then carried to the output grid by
    :func:`~torch_depth_sr.upsampling.bounded_upsample` (``upsampling``); Q⁰ = measured."""

    def __init__(self, settings: InitConfig, sided_fill: Optional[SidedFill], upsampling: UpsamplingConfig,
                 nonlocal_: bool):
        super().__init__(settings, sided_fill, matches=nonlocal_, nonlocal_=nonlocal_)
        self.upsampling = upsampling

    def forward(self, obs: Observation) -> InitialEstimate:
        guided, confident = self.guided(obs)
        x0_lr = self.observation_grid(obs, guided)
        ref = upsampling_reference(x0_lr, obs.observed, obs.rgb, obs.K.scale, self.upsampling)
        x0 = bounded_upsample(ref, obs.K, self.upsampling, noise=obs.noise)
        state = self.start(x0, obs, obs.observed, obs.observed, None)
        return InitialEstimate(state, confident, reference=ref)

    def extra_repr(self) -> str:
        return super().extra_repr() + f", upsampling={self.upsampling.init!r}"


# ---- what the settings choose, once, when a stage is built ------------------------------------------------
def _keep_measured(obs: Observation, guided: torch.Tensor) -> torch.Tensor:
    return torch.where(obs.observed > 0, obs.y, guided)


def _guided_only(obs: Observation, guided: torch.Tensor) -> torch.Tensor:
    return guided


def _match(x0: torch.Tensor, obs: Observation):
    return obs.block_matcher(x0, obs, obs.observed)


def _no_matches(x0: torch.Tensor, obs: Observation) -> None:
    return None


def _alpha(x0: torch.Tensor, matches, zeros2: torch.Tensor) -> torch.Tensor:
    return nonlocal_gradient(grad(x0), matches)  # α alone: nonlocal_terms' α without its value statistics


def _no_alpha(x0: torch.Tensor, matches, zeros2: torch.Tensor) -> torch.Tensor:
    return zeros2


def _support(init: DenoiseInit, obs: Observation) -> Optional[torch.Tensor]:
    return init.singular.supported(obs)


def _no_support(init: DenoiseInit, obs: Observation) -> None:
    return None


def _measured(init: DenoiseInit, obs: Observation, guided: torch.Tensor):
    """x⁰ with the measurements kept (``keep_observed``), Q⁰ = measured, no verdict of a gate."""
    return init.observation_grid(obs, guided), obs.observed, obs.observed, None


def _tested(init: DenoiseInit, obs: Observation, guided: torch.Tensor):
    """Q⁰ from the singular-pixel test against the guided estimate, whose matches are cleaner than those of the raw
    input; singular pixels start from the guided value instead of y (with a colour image)."""
    if obs.rgb is None:
        return _measured(init, obs, guided)
    q, conf, clean = init.singular(obs, guided, obs.block_matcher(guided, obs, obs.observed))
    return torch.where(q > 0, obs.y, guided), q, conf, clean


def _guided_estimate(guided: torch.Tensor) -> torch.Tensor:
    return guided


def _no_prior(guided: torch.Tensor) -> None:
    return None


def initial_stages(config: RestorerConfig, singular: Optional[SingularDetector]) -> nn.ModuleDict:
    """The initial stage per task; ``singular`` is the model's detector when the layers run the singular test."""
    nonlocal_ = config.uses("nonlocal")
    return nn.ModuleDict({
        "denoise": DenoiseInit(config.initial, config.sided_fill, singular, config.guided_prior is not None,
                               nonlocal_),
        "upsample": UpsampleInit(config.initial, config.sided_fill, config.upsampling, nonlocal_)})
