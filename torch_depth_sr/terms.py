r"""The terms of one unrolled layer's objective, each an object the layer sums (model.md, Algorithm 3.1).

A layer works in three phases, and a term takes part in those it needs:

1. :meth:`Term.split` updates the term's split variable from the current estimate: TV :math:`z =
   \operatorname{soft}(Dx, \lambda/\mu_1)`, nonlocal :math:`w = \operatorname{soft}(Dx-\alpha, \eta/\mu_2)`,
   outliers :math:`e = Q\odot\operatorname{soft}(y-Kx, \gamma)`;
2. the matches are read once (:class:`MatchReader`): the nonlocal gradient :math:`\alpha` and the value prior's
   weights and target :math:`(W, \bar x)`; the singular test sets :math:`Q`;
3. :meth:`Term.system` adds the term's share of the x-update's linear system
   :math:`(K^\top QK + \textstyle\sum \mathrm{diag} + \mu D^\top D)\,x = K^\top Q(y-e) + \sum \mathrm{rhs}`.

The order of the list is the order of the sums (floating point: the order is part of the result).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

import torch
from torch import nn

from .block_matching import BlockMatches
from .config import CleanSamples, GuidedPrior, ValuePrior
from .nonlocal_prior import nonlocal_terms
from .observation import Observation
from .operators import grad_adjoint
from .shrinkage import group_soft_threshold, soft_threshold
from .state import RestorationState, stage

__all__ = ["GuidedPriorTerm", "LayerStep", "MatchReader", "NonlocalTerm", "OutlierTerm", "System", "TVTerm",
           "Term", "ValuePriorTerm"]


@dataclass
class LayerStep:
    """One layer's working values: the weights (λ, η, γ, μ₁, μ₂ for this task), the state it started from, Dx,
    the residual, the guidance multipliers; then the new split variables, α and the value prior's (W, x̄)."""

    state: RestorationState
    lam: torch.Tensor
    eta: torch.Tensor
    gamma: torch.Tensor
    mu1: torch.Tensor
    mu2: torch.Tensor
    dx: torch.Tensor  # (B,2,H,W)
    residual: torch.Tensor  # (B,1,h,w) y − Kx
    maps: Any  # GuidanceMaps, or unit multipliers without a guidance network
    z: Optional[torch.Tensor] = None
    w: Optional[torch.Tensor] = None
    e: Optional[torch.Tensor] = None
    alpha: Optional[torch.Tensor] = None  # α read from this layer's matches
    value_weight: Optional[torch.Tensor] = None  # W of the value prior
    value_target: Optional[torch.Tensor] = None  # x̄


@dataclass
class System:
    """The x-update's system as the terms add to it: right-hand side, diagonal (None = 0) and μ of μDᵀD."""

    rhs: torch.Tensor
    diag: Optional[torch.Tensor]
    mu: Optional[torch.Tensor] = None

    def add(self, rhs: torch.Tensor, diag: Optional[torch.Tensor] = None, mu: Optional[torch.Tensor] = None) -> None:
        self.rhs = self.rhs + rhs
        if diag is not None:
            self.diag = diag if self.diag is None else self.diag + diag
        if mu is not None:
            self.mu = mu if self.mu is None else self.mu + mu


class Term(nn.Module):
    """A term of the objective; the phases it does not take part in do nothing."""

    def split(self, step: LayerStep, obs: Observation) -> None:
        """Phase 1: update the term's split variable in ``step``."""

    def system(self, step: LayerStep, obs: Observation, q: torch.Tensor, out: System) -> None:
        """Phase 3: add the term's share of the linear system (``q``: this layer's trusted set)."""


class TVTerm(Term):
    r"""λ‖Dx‖₁ by the split :math:`z \approx Dx`: anisotropic, or isotropic (group) shrinkage."""

    def __init__(self, isotropic: bool):
        super().__init__()
        self.isotropic = isotropic
        # the group threshold takes the geometric mean of the two directions' guidance multipliers
        self.shrink = group_soft_threshold if isotropic else soft_threshold
        self.multiplier = _geometric_mean if isotropic else _per_direction

    def split(self, step: LayerStep, obs: Observation) -> None:
        step.z = self.shrink(step.dx, step.lam / step.mu1 * self.multiplier(step.maps.tv))

    def system(self, step: LayerStep, obs: Observation, q: torch.Tensor, out: System) -> None:
        out.add(step.mu1 * grad_adjoint(step.z), mu=step.mu1)

    def extra_repr(self) -> str:
        return f"isotropic={self.isotropic}"


class NonlocalTerm(Term):
    r"""η‖Dx − α‖₁ by the split :math:`w \approx Dx-\alpha` (α from the matches); on samples the singular gate
    finds clean, η times ``clean.eta``."""

    def __init__(self, clean: Optional[CleanSamples]):
        super().__init__()
        self.clean_eta = None if clean is None else clean.eta

    def split(self, step: LayerStep, obs: Observation) -> None:
        eta, clean = step.eta, step.state.clean
        if clean is not None and self.clean_eta is not None:  # samples without outliers: α matters less
            eta = eta * torch.where(clean, torch.full_like(eta, self.clean_eta), torch.ones_like(eta))
        step.w = soft_threshold(step.dx - step.state.alpha, eta / step.mu2 * step.maps.nonlocal_)

    def system(self, step: LayerStep, obs: Observation, q: torch.Tensor, out: System) -> None:
        out.add(step.mu2 * grad_adjoint(step.w + step.alpha), mu=step.mu2)


class OutlierTerm(Term):
    """γ‖e‖₁: the sparse outliers of the residual on trusted pixels (the data term reads e)."""

    def split(self, step: LayerStep, obs: Observation) -> None:
        step.e = step.state.q * soft_threshold(step.residual, step.gamma * step.maps.outlier)


class GuidedPriorTerm(Term):
    """β(1−Q)/2‖x − x_g‖²: untrusted pixels (missing, and singular ones with ``on_singular``) pulled to the
    colour-guided estimate ``obs.prior`` (denoising; nothing without a guide)."""

    def __init__(self, settings: GuidedPrior):
        super().__init__()
        self.settings = settings

    def system(self, step: LayerStep, obs: Observation, q: torch.Tensor, out: System) -> None:
        if obs.prior is None:  # no colour image: no guided estimate
            return
        untrusted = (1 - q) if self.settings.on_singular else (1 - obs.observed)
        beta = self.settings.weight * untrusted
        out.add(beta * obs.prior, diag=beta)

    def extra_repr(self) -> str:
        return f"weight={self.settings.weight:g}, on_singular={self.settings.on_singular}"


class ValuePriorTerm(Term):
    """η₃/2‖x − x̄‖² on pixels whose matched values agree (denoising; :class:`MatchReader` computes W and x̄)."""

    def system(self, step: LayerStep, obs: Observation, q: torch.Tensor, out: System) -> None:
        if step.value_weight is not None:
            out.add(step.value_weight * step.value_target, diag=step.value_weight)


class MatchReader(nn.Module):
    """One read of the matches for the terms that need them
    (:func:`~torch_depth_sr.nonlocal_prior.nonlocal_terms`): α for the nonlocal term, and W, x̄ for the value prior,
    whose range σ and weight change on clean samples (``clean``)."""

    def __init__(self, alpha: bool, value: Optional[ValuePrior], clean: Optional[CleanSamples]):
        super().__init__()
        self.alpha, self.value = alpha, value
        self.gates = value or ValuePrior()  # the gates nonlocal_terms reads (no effect on α)
        self.clean = clean

    def forward(self, step: LayerStep, matches: BlockMatches, obs: Observation) -> None:
        x, clean = step.state.x, step.state.clean
        vp = self.gates
        with stage(obs.log.timings, "nonlocal", x.device):
            alpha, diag, target = nonlocal_terms(
                x, step.dx if self.alpha else None, matches, value_weight=vp.weight if self.value else 0.0,
                max_var=vp.var, max_offset=vp.offset, plane_ridge=vp.ridge, range_sigma=self._range_sigma(clean))
        step.alpha = alpha if self.alpha else step.state.alpha
        weight_clean = None if self.clean is None else self.clean.value_weight
        if diag is not None and clean is not None and weight_clean is not None and weight_clean != vp.weight:
            diag = diag * torch.where(clean, weight_clean / vp.weight, 1.0).to(diag.dtype)
        step.value_weight, step.value_target = diag, target

    def _range_sigma(self, clean: Optional[torch.Tensor]) -> Optional[float | torch.Tensor]:
        """The value prior's range σ, per sample ``clean.value_range`` where the gate found no outliers."""
        r = self.gates.range
        r_clean = None if self.clean is None else self.clean.value_range
        if r is None:
            return None
        if clean is None or r_clean is None:
            return r
        return torch.where(clean, float(r_clean), float(r))

    def extra_repr(self) -> str:
        return f"alpha={self.alpha}, value_prior={self.value is not None}"


def _per_direction(m: Any) -> Any:
    return m


def _geometric_mean(m: Any) -> Any:
    return m.prod(1, keepdim=True).sqrt() if isinstance(m, torch.Tensor) else m
