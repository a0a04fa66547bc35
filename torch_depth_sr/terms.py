r"""The terms of one unrolled layer's objective, each an object the layer sums (model.md, Algorithm 3.1).

A layer works in three phases, and a term takes part in those it needs:

1. :meth:`Term.split` updates the term's split variable from the current estimate: TV :math:`z =
   \operatorname{soft}(Dx, \lambda/\mu_1)`, nonlocal :math:`w = \operatorname{soft}(Dx-\alpha, \eta/\mu_2)`,
   outliers :math:`e = Q\odot\operatorname{soft}(y-Kx, \gamma)`;
2. the steps of the layer between the split updates and the x-update: re-matching when scheduled (:class:`Rematch`),
   one read of the matches (:class:`MatchReader`: the nonlocal gradient :math:`\alpha` and the value prior's
   weights and target :math:`(W, \bar x)`), the singular test that sets :math:`Q` (:class:`SingularTest`);
3. :meth:`Term.system` adds the term's share of the x-update's linear system
   :math:`(K^\top QK + \textstyle\sum \mathrm{diag} + \mu D^\top D)\,x = K^\top Q(y-e) + \sum \mathrm{rhs}`.

The order of the list is the order of the sums (floating point: the order is part of the result).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from typing import Any, Callable, Optional

import torch
from torch import nn

from .block_matching import BlockMatches
from .config import CleanSamples, GuidedPrior, SingularConfig, StreamConfig, ValuePrior
from .nonlocal_prior import nonlocal_terms
from .observation import Observation
from .operators import grad_adjoint
from .shrinkage import group_soft_threshold, soft_threshold
from .stages import SingularDetector
from .state import RestorationState, stage
from .window_max import dilate

__all__ = ["GuidedPriorTerm", "LayerStep", "MatchReader", "NonlocalTerm", "OutlierTerm", "Rematch", "SingularTest",
           "System", "TVTerm", "TemporalPriorTerm", "Term", "ValuePriorTerm"]


@dataclass
class LayerStep:
    """One layer's working values: the weights (λ, η, γ, μ₁, μ₂ for this task), the state it started from, Dx,
    the residual, the guidance multipliers; then the new split variables, matches, α, the value prior's (W, x̄) and
    the singular test's Q, confidence and verdict (each starts as the state's)."""

    state: RestorationState
    lam: torch.Tensor
    eta: torch.Tensor
    gamma: torch.Tensor
    mu1: torch.Tensor
    mu2: torch.Tensor
    dx: torch.Tensor  # (B,2,H,W)
    residual: torch.Tensor  # (B,1,h,w) y − Kx
    maps: Any  # GuidanceMaps, or unit multipliers without a guidance network
    tv_threshold: Any = None  # λ/μ₁ times its guidance multipliers
    outlier_threshold: Any = None  # γ times its guidance multiplier
    z: Optional[torch.Tensor] = None
    w: Optional[torch.Tensor] = None
    e: Optional[torch.Tensor] = None
    alpha: Optional[torch.Tensor] = None  # α read from this layer's matches
    value_weight: Optional[torch.Tensor] = None  # W of the value prior
    value_target: Optional[torch.Tensor] = None  # x̄
    matches: Optional[BlockMatches] = None
    q: Optional[torch.Tensor] = None  # (B,1,h,w) trusted set
    confidence: Optional[torch.Tensor] = None
    clean: Optional[torch.Tensor] = None  # (B,1,1,1) the gate's verdict


@dataclass
class System:
    """The x-update's system as the terms add to it: right-hand side, diagonal (None = 0) and μ of μDᵀD (the TV
    term's μ₁ first). Nothing is added that a term did not contribute: no zeros, so that the gradients flow through
    the same operations whichever terms there are."""

    rhs: torch.Tensor
    diag: Optional[torch.Tensor] = None
    mus: list = field(default_factory=list)

    def add(self, rhs: torch.Tensor, diag: Optional[torch.Tensor] = None) -> None:
        self.rhs = self.rhs + rhs
        if diag is not None:
            self.diag = diag if self.diag is None else self.diag + diag

    def add_mu(self, mu: torch.Tensor) -> None:
        self.mus.append(mu)

    def mu(self) -> torch.Tensor:
        """μ of μDᵀD, summed when the system is solved."""
        return sum(self.mus[1:], self.mus[0])


class Term(nn.Module):
    """A term of the objective; the phases it does not take part in do nothing."""

    def split(self, step: LayerStep, obs: Observation) -> None:
        """Phase 1: update the term's split variable in ``step``."""

    def system(self, step: LayerStep, obs: Observation, out: System) -> None:
        """Phase 3: add the term's share of the linear system (``step.q``: this layer's trusted set)."""


class TVTerm(Term):
    r"""λ‖Dx‖₁ by the split :math:`z \approx Dx`: anisotropic, or isotropic (group) shrinkage."""

    def __init__(self, isotropic: bool):
        super().__init__()
        self.isotropic = isotropic
        self.shrink = group_soft_threshold if isotropic else soft_threshold

    def split(self, step: LayerStep, obs: Observation) -> None:
        step.z = self.shrink(step.dx, step.tv_threshold)

    def system(self, step: LayerStep, obs: Observation, out: System) -> None:
        out.add(step.mu1 * grad_adjoint(step.z))
        out.add_mu(step.mu1)

    def extra_repr(self) -> str:
        return f"isotropic={self.isotropic}"


class NonlocalTerm(Term):
    r"""η‖Dx − α‖₁ by the split :math:`w \approx Dx-\alpha` (α from the matches); on samples the singular gate
    finds clean, η times ``clean.eta``."""

    def __init__(self, clean: Optional[CleanSamples]):
        super().__init__()
        self.clean = clean
        self._eta = _eta if clean is None else _eta_on_clean_samples

    def split(self, step: LayerStep, obs: Observation) -> None:
        eta = self._eta(step.eta, step.state.clean, self.clean)
        step.w = soft_threshold(step.dx - step.state.alpha, step.maps.nonlocal_threshold(eta / step.mu2))

    def extra_repr(self) -> str:
        return "" if self.clean is None else f"clean_eta={self.clean.eta:g}"

    def system(self, step: LayerStep, obs: Observation, out: System) -> None:
        out.add(step.mu2 * grad_adjoint(step.w + step.alpha))
        out.add_mu(step.mu2)


class OutlierTerm(Term):
    """γ‖e‖₁: the sparse outliers of the residual on trusted pixels (the data term reads e)."""

    def split(self, step: LayerStep, obs: Observation) -> None:
        step.e = step.state.q * soft_threshold(step.residual, step.outlier_threshold)


class GuidedPriorTerm(Term):
    """β(1−Q)/2‖x − x_g‖²: untrusted pixels (missing, and singular ones with ``on_singular``) pulled to the
    colour-guided estimate ``obs.prior`` (denoising; nothing without a guide)."""

    def __init__(self, settings: GuidedPrior):
        super().__init__()
        self.settings = settings
        self._untrusted = _untrusted if settings.on_singular else _missing

    def system(self, step: LayerStep, obs: Observation, out: System) -> None:
        if obs.rgb is None:  # no colour image: no guided estimate
            return
        beta = self.settings.weight * self._untrusted(step.q, obs.observed)
        out.add(beta * obs.prior, diag=beta)

    def extra_repr(self) -> str:
        return f"weight={self.settings.weight:g}, on_singular={self.settings.on_singular}"


class TemporalPriorTerm(Term):
    """½‖W^½ (x − x_prev)‖²: a stream's previous estimate ``obs.temporal.target`` pulls x with the per-pixel weight
    ``obs.temporal.weight`` (the settings' weight times the evidence of static pixels, 0 where the scene changed;
    :mod:`torch_depth_sr.stream`). Denoising; nothing without a previous frame (``obs.temporal`` None), so the first
    frame of a stream is the per-frame model's."""

    def __init__(self, settings: StreamConfig):
        super().__init__()
        self.settings = settings

    def system(self, step: LayerStep, obs: Observation, out: System) -> None:
        prior = obs.temporal
        if prior is None:
            return
        out.add(prior.weight * prior.target, diag=prior.weight)

    def extra_repr(self) -> str:
        return f"weight={self.settings.weight:g}, max_frames={self.settings.max_frames:g}"


class ValuePriorTerm(Term):
    """η₃/2‖x − x̄‖² on pixels whose matched values agree (denoising; :class:`MatchReader` computes W and x̄)."""

    def system(self, step: LayerStep, obs: Observation, out: System) -> None:
        out.add(step.value_weight * step.value_target, diag=step.value_weight)


class MatchReader(nn.Module):
    """One read of the matches for the terms that need them
    (:func:`~torch_depth_sr.nonlocal_prior.nonlocal_terms`): α for the nonlocal term (``alpha``), and W, x̄ for the
    value prior (``value``), whose range σ and weight change on clean samples (``clean``)."""

    def __init__(self, alpha: bool, value: Optional[ValuePrior], clean: Optional[CleanSamples]):
        super().__init__()
        self.alpha, self.value, self.clean = alpha, value, clean
        self.gates = value or ValuePrior()  # the gates nonlocal_terms reads (no effect on α)
        self.value_weight = 0.0 if value is None else value.weight
        self._gradient = _gradient if alpha else _no_gradient
        self._alpha = _new_alpha if alpha else _old_alpha
        clean = clean or CleanSamples(value_range=None, value_weight=None)
        self._range = _range_sigma(self.gates.range, clean.value_range)
        self._weight = _weight_on_clean_samples(self.gates.weight, clean.value_weight, value is not None)

    def forward(self, step: LayerStep, obs: Observation) -> None:
        x, clean, vp = step.state.x, step.state.clean, self.gates
        with stage(obs.log.timings, "nonlocal", x.device):
            # with an update region, the x-update reads α one pixel beyond it (Dᵀ) and W, x̄ in it: the kernel
            # computes those pixels alone
            region = None if obs.update_region is None else dilate(obs.update_region, 1)
            alpha, diag, target = nonlocal_terms(
                x, self._gradient(step), step.matches, value_weight=self.value_weight, max_var=vp.var,
                max_offset=vp.offset, plane_ridge=vp.ridge, range_sigma=self._range(clean), region=region)
        step.alpha = self._alpha(alpha, step)
        step.value_weight, step.value_target = self._weight(diag, clean), target

    def extra_repr(self) -> str:
        return f"alpha={self.alpha}, value_prior={self.value is not None}, clean_samples={self.clean is not None}"


class Rematch(nn.Module):
    """Block matching again on the current estimate (a layer of ``block_matching.match_layers``)."""

    def forward(self, step: LayerStep, obs: Observation) -> None:
        step.matches = obs.block_matcher.rematch(step.state.x, obs, step.state.q, step.matches)


class SingularTest(nn.Module):
    """The singular-pixel test of the current estimate: Q, its confidence and the gate's verdict
    (:class:`~torch_depth_sr.stages.SingularDetector`)."""

    def __init__(self, settings: SingularConfig):
        super().__init__()
        self.detector = SingularDetector(settings)

    def forward(self, step: LayerStep, obs: Observation) -> None:
        s = step.state
        held = None if s.q is None or s.confidence is None else (s.q, s.confidence, s.clean)
        step.q, step.confidence, step.clean = self.detector(obs, s.x, step.matches, held)


# ---- what the settings choose, once, when a term is built -----------------------------------------------
def _eta(eta: torch.Tensor, clean: Optional[torch.Tensor], settings: Optional[CleanSamples]) -> torch.Tensor:
    return eta


def _eta_on_clean_samples(eta: torch.Tensor, clean: Optional[torch.Tensor], settings: CleanSamples) -> torch.Tensor:
    """η times ``settings.eta`` on the samples the last gated test found clean (none before the first test):
    there α (a mean over matched blocks) blurs edges more than it helps."""
    if clean is None:
        return eta
    return eta * torch.where(clean, torch.full_like(eta, settings.eta), torch.ones_like(eta))


def _untrusted(q: torch.Tensor, observed: torch.Tensor) -> torch.Tensor:
    return 1 - q


def _missing(q: torch.Tensor, observed: torch.Tensor) -> torch.Tensor:
    return 1 - observed


def _gradient(step: LayerStep) -> torch.Tensor:
    return step.dx


def _no_gradient(step: LayerStep) -> None:
    return None


def _new_alpha(alpha: torch.Tensor, step: LayerStep) -> torch.Tensor:
    return alpha


def _old_alpha(alpha: Optional[torch.Tensor], step: LayerStep) -> torch.Tensor:
    return step.state.alpha


def _range_sigma(r: Optional[float], r_clean: Optional[float]) -> Callable:
    """The value prior's range σ as a function of the gate's verdict: ``r``, per sample ``r_clean`` where the last
    gated test found no outliers; None = no range kernel."""
    return partial(_fixed_range, r) if r is None or r_clean is None else partial(_range_per_sample, r, r_clean)


def _fixed_range(r: Optional[float], clean: Optional[torch.Tensor]) -> Optional[float]:
    return r


def _range_per_sample(r: float, r_clean: float, clean: Optional[torch.Tensor]) -> float | torch.Tensor:
    return r if clean is None else torch.where(clean, float(r_clean), float(r))


def _weight_on_clean_samples(weight: float, weight_clean: Optional[float], value: bool) -> Callable:
    """The value prior's weights W as a function of the gate's verdict: η₃ = ``weight_clean`` instead of ``weight``
    on the samples the last gated test found clean."""
    if value and weight_clean is not None and weight_clean != weight:
        return partial(_weight_per_sample, weight_clean / weight)
    return _same_weight


def _same_weight(diag: Optional[torch.Tensor], clean: Optional[torch.Tensor]) -> Optional[torch.Tensor]:
    return diag


def _weight_per_sample(ratio: float, diag: torch.Tensor, clean: Optional[torch.Tensor]) -> torch.Tensor:
    return diag if clean is None else diag * torch.where(clean, ratio, 1.0).to(diag.dtype)
