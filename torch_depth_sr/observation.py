"""What stays fixed during one forward: the :class:`Observation` (the normalised measurement, where it was measured,
the guide, the degradation ``K`` and the task it stands for, the noise level), built once by :func:`observe` — the
scale policy and the one place that decides the task — and never written to afterwards. The stages that compute
something the later ones read (the guided prior's target, the supported pixels, the guidance features) return it,
and the model hands it on in a new observation (``dataclasses.replace``)."""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any, NamedTuple, Optional

import torch

from ._checks import check_noise_sigma
from .noise import depth_scale, implausible, policy_scale, quantisation_step, sample_percentiles, white_noise_sigma
from .native import host_path
from .operators import Degradation
from .state import RunLog

__all__ = ["Observation", "ScalePolicy", "TASKS", "observe"]

TASKS = ("denoise", "upsample")
"""``"denoise"``: K is the identity (restoration on the observation grid); ``"upsample"``: K downsamples."""


class ScalePolicy(NamedTuple):
    """An observation's scale policy, each (B,) but ``percentiles`` (B,2): what :func:`observe` estimates of a frame,
    and what a stream hands to its next frame while the scene stays (``StreamConfig.keep_scale``)."""

    offset: torch.Tensor  # the lower median of the measured depth
    scale: torch.Tensor  # the unit of the normalised depth (noise_scale.policy_scale)
    sigma: torch.Tensor  # the noise σ in depth units
    step: torch.Tensor  # the quantisation step (0 = none)
    percentiles: torch.Tensor  # p1 and p99 of the measured depth (the implausible-value test)


@dataclass(frozen=True)
class Observation:
    """The measurement in units of its scale and everything a forward reads but does not change."""

    y: torch.Tensor  # (B,1,h,w) normalised observation (y − offset) / scale, 0 where missing
    observed: torch.Tensor  # (B,1,h,w) {0,1}: measured and plausible
    rgb: Optional[torch.Tensor]  # (B,3,H,W) guide on the output grid, or None
    K: Degradation  # from the output grid (H,W) to the observation grid (h,w)
    task: str  # "denoise" (K = I) or "upsample"
    raw: torch.Tensor  # (B,1,h,w) the measurement in its own units
    offset: torch.Tensor  # (B,)
    scale: torch.Tensor  # (B,)
    sigma: torch.Tensor  # (B,) noise σ in depth units (given, or estimated)
    step: torch.Tensor  # (B,) quantisation step in depth units (0 = none)
    glitches: torch.Tensor  # (B,1,h,w) bool: implausible values, taken as missing
    sigma_given: bool  # whether the caller gave the noise level
    block_matcher: Any  # the model's BlockMatcher (settings, h and ρ): x⁰'s matches and every scheduled layer's
    log: RunLog  # CG iterations and stage timings of this forward
    # returned by the stages before the layers
    prior: Optional[torch.Tensor] = None  # (B,1,H,W) guided estimate untrusted pixels are pulled to (GuidedPrior)
    supported: Optional[torch.Tensor] = None  # (B,1,h,w) bool: pixels the singular test always trusts
    guidance: Any = None  # the guidance network with this forward's colour features, or NoGuidance
    temporal: Any = None  # a stream's previous frame (stream.TemporalPrior: target, weight), None = none
    # (B,1,h,w) bool: pixels whose share of gross failures the singular gate also reads on its own (a stream: those
    # measured in this frame alone, not a run's mean); None: the gate reads the whole frame only
    gate_region: Optional[torch.Tensor] = None
    # (B,1,h,w) bool: measurements the singular test does not trust, whatever it finds (a stream's measurements of
    # this frame alone without the support of their neighbours, ``StreamConfig.single_support``); None: none
    untrusted: Optional[torch.Tensor] = None
    # (B,1,H,W) bool: the pixels a layer updates; every other pixel keeps the state it comes in with (the x-update
    # solves for these pixels alone, the others fixed; the stages compute what these pixels read). None: every pixel
    update_region: Optional[torch.Tensor] = None
    percentiles: Optional[torch.Tensor] = None  # (B,2) p1 and p99 of the measured depth (the scale policy's)

    @property
    def policy(self) -> ScalePolicy:
        """The scale policy this observation was normalised with."""
        return ScalePolicy(self.offset, self.scale, self.sigma, self.step, self.percentiles)

    @property
    def grid_step(self) -> torch.Tensor:
        """(B,) the quantisation step in units of the scale."""
        return self.step / self.scale

    @property
    def noise(self) -> torch.Tensor:
        """(B,) the noise σ in units of the scale."""
        return self.sigma / self.scale

    @cached_property
    def white(self) -> torch.Tensor:
        """(B,) the white part of the noise in depth units (:func:`~torch_depth_sr.noise.white_noise_sigma`; the
        given σ when the caller gave one), computed on first use: only the upsampling post-steps read it."""
        return self.sigma if self.sigma_given else white_noise_sigma(self.raw, self.observed)

    def normalise(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.offset.view(-1, 1, 1, 1)) / self.scale.view(-1, 1, 1, 1)

    def denormalise(self, x: torch.Tensor) -> torch.Tensor:
        """``x`` from units of the scale back to depth units."""
        return x * self.scale.view(-1, 1, 1, 1) + self.offset.view(-1, 1, 1, 1)


def observe(y: torch.Tensor, observed: torch.Tensor, guide: Optional[torch.Tensor], K: Degradation,
            noise_sigma: Any, integer_input: bool, block_matcher: Any, timed: bool,
            policy: Optional[ScalePolicy] = None) -> Observation:
    """The scale policy: quantisation step, noise σ̂, offset and scale of ``y (B,1,h,w)``, implausible values
    (glitches) taken as missing and the scale estimated again without them; the task from ``K``. With ``policy``
    (a stream's previous frame, :class:`ScalePolicy`) nothing is estimated: the frame is normalised with it (a
    ``noise_sigma`` given still sets σ and the scale), unless a measurement of the frame lies outside the range that
    policy calls plausible. That sample's policy is then estimated again, as without one: a new object nearer or
    farther than everything the still scene held is a surface, not a glitch of the sensor (kept, the policy took a
    person arriving 0.8 m in front of a wall for glitches, and the stream filled them with the wall behind)."""
    b = y.shape[0]
    if policy is None:
        offset, scale, sigma, step, percentiles, glitches = _estimated(y, observed, noise_sigma, integer_input)
    else:
        offset, scale, sigma, step, percentiles, glitches = _kept(y, observed, noise_sigma, integer_input, policy)
    observed = torch.where(glitches, torch.zeros_like(observed), observed)
    o4, s4 = offset.view(b, 1, 1, 1), scale.view(b, 1, 1, 1)
    yn = torch.where(observed > 0, (y - o4) / s4, torch.zeros_like(y))
    return Observation(y=yn, observed=observed, rgb=guide, K=K, task="denoise" if K.is_identity else "upsample",
                       raw=y, offset=offset, scale=scale, sigma=sigma, step=step, glitches=glitches,
                       sigma_given=noise_sigma is not None, block_matcher=block_matcher,
                       log=RunLog(timings={} if timed else None), percentiles=percentiles)


def _estimated(y: torch.Tensor, observed: torch.Tensor, noise_sigma: Any, integer_input: bool) -> tuple:
    """``(offset, scale, sigma, step, percentiles, glitches)`` estimated from the frame, each (B,) but the
    percentiles (B,2) and the glitches (B,1,h,w)."""
    b = y.shape[0]
    step = quantisation_step(y, observed, integer_input=integer_input)
    percentiles = sample_percentiles(y, observed)
    offset, scale, sigma = depth_scale(y, observed, check_noise_sigma(noise_sigma, b), step=step,
                                       percentiles=percentiles)
    glitches = implausible(y, observed, scale, percentiles=percentiles)
    # a glitch is a missing measurement: the scale as if it had never been there. Off the CPU the scale is estimated
    # again whatever the glitches (without any it comes out the same): asking would make the host wait for the device
    if not host_path(y.device) or bool(glitches.any()):
        observed = torch.where(glitches, torch.zeros_like(observed), observed)
        step = quantisation_step(y, observed, integer_input=integer_input)
        offset, scale, sigma = depth_scale(y, observed, check_noise_sigma(noise_sigma, b), step=step)
    return offset, scale, sigma, step, percentiles, glitches


def _kept(y: torch.Tensor, observed: torch.Tensor, noise_sigma: Any, integer_input: bool,
          policy: ScalePolicy) -> tuple:
    """What :func:`_estimated` returns, from ``policy`` where every measurement of the sample is plausible under
    it, else estimated again. On the CPU the frame is estimated only when a sample needs it; elsewhere always (asking
    would make the host wait for the device), and each sample takes its own."""
    b = y.shape[0]
    offset, _, sigma, step, percentiles = policy
    if noise_sigma is not None:
        given = check_noise_sigma(noise_sigma, b)
        sigma = torch.as_tensor(given, dtype=y.dtype, device=y.device).expand(b).clone()
    scale = policy_scale(sigma, percentiles[:, 1] - percentiles[:, 0], offset)
    glitches = implausible(y, observed, scale, percentiles=percentiles)
    outside = glitches.flatten(1).any(1)  # (B,): a measurement the kept policy calls implausible
    if host_path(y.device) and not bool(outside.any()):
        return offset, scale, sigma, step, percentiles, glitches
    fresh = _estimated(y, observed, noise_sigma, integer_input)
    kept = (offset, scale, sigma, step, percentiles, glitches)
    return tuple(torch.where(outside.view(-1, *([1] * (k.dim() - 1))), f, k) for f, k in zip(fresh, kept))
