r"""One unrolled iteration of the half-quadratic splitting (model.md, Algorithm 3.1).

With :math:`z \approx Dx` and :math:`w \approx Dx-\alpha`, layer :math:`k` updates, in this order,

.. math::
    z &= \operatorname{soft}(Dx, \lambda_k/\mu_{1,k}) \\
    w &= \operatorname{soft}(Dx-\alpha, \eta_k/\mu_{2,k}) \\
    e &= Q \odot \operatorname{soft}(y-Kx, \gamma_k) \\
    \alpha &= \textstyle\sum_j \omega_{ij} D_j x \quad\text{(block matching when scheduled)} \\
    Q &= \text{singular-pixel test} \\
    x &= (K^\top Q K + (\mu_{1,k}+\mu_{2,k}) D^\top D)^{-1}
         \big(K^\top Q (y-e) + \mu_{1,k} D^\top z + \mu_{2,k} D^\top (w+\alpha)\big)

Each term is an object of :mod:`torch_depth_sr.terms`; the layer holds one list per task (the value prior, the
guided prior and the singular test act on the observation grid, so only when denoising) and sums what its terms
contribute. ``K`` is the :class:`~torch_depth_sr.operators.Degradation` of the observation; the layer applies it and
its adjoint.
"""
from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple, Optional

import torch
import torch.nn.functional as F
from torch import nn

from .config import LayerMultipliers, RestorerConfig, UpsamplingConfig
from .observation import TASKS, Observation
from .operators import Degradation, grad
from .stages import LinearSolver, SingularDetector
from .state import RestorationState
from .terms import (GuidedPriorTerm, LayerStep, MatchReader, NonlocalTerm, OutlierTerm, System, TVTerm,
                    ValuePriorTerm)

__all__ = ["UnrolledLayer", "terms_for"]


def _inv_softplus(v: float) -> float:
    v = float(v)
    return v + torch.log(-torch.expm1(torch.tensor(-v))).item() if v < 20 else v


class _UnitMultipliers(NamedTuple):
    """The guidance multipliers of a model without a guidance network: every threshold times 1 (exactly)."""

    tv: float = 1.0
    nonlocal_: float = 1.0
    outlier: float = 1.0


def terms_for(config: RestorerConfig, task: str) -> nn.ModuleList:
    """The terms a layer sums for ``task``, in the order of the sums."""
    denoise = task == "denoise"
    terms: list = [TVTerm(config.weights.isotropic)]
    if denoise and config.guided_prior is not None:
        terms.append(GuidedPriorTerm(config.guided_prior))
    if config.uses("nonlocal"):
        terms.append(NonlocalTerm(config.clean_samples))
    if denoise and config.value_prior is not None:
        terms.append(ValuePriorTerm())
    if config.uses("outliers"):
        terms.append(OutlierTerm())
    return nn.ModuleList(terms)


def _match_reader(config: RestorerConfig, task: str) -> Optional[MatchReader]:
    value = config.value_prior if task == "denoise" else None
    if not config.uses("nonlocal") and value is None:
        return None
    return MatchReader(config.uses("nonlocal"), value, config.clean_samples)


class UnrolledLayer(nn.Module):
    """One iteration; owns its positive parameters λ, η, γ, μ₁, μ₂ (softplus of raw values) and, per task
    (``"denoise"``, ``"upsample"``), its terms (``terms[task]``), the reader of the matches (``match_readers``) and the
    singular test (``singular_tests``, denoising only), and the solver of the x-update. It matches through the model's
    :class:`~torch_depth_sr.stages.BlockMatcher` (``obs.block_matcher``, which owns the temperature h shared by all
    layers) when that schedules this layer."""

    names = ("lam", "eta", "gamma", "mu1", "mu2")

    def __init__(self, config: RestorerConfig, index: int, trainable: bool = False):
        super().__init__()
        self.index = index
        self.upsampling: UpsamplingConfig = config.upsampling  # the weights' policy under guided upsampling
        self.terms = nn.ModuleDict({task: terms_for(config, task) for task in TASKS})
        self.match_readers = nn.ModuleDict({t: r for t in TASKS if (r := _match_reader(config, t)) is not None})
        # the singular test compares the estimate with the observation pixel by pixel: denoising only
        self.singular_tests = nn.ModuleDict({"denoise": SingularDetector(config.singular)}
                                            if config.uses("singular") else {})
        self.linear_solver = LinearSolver(config.solver)
        for n in self.names:
            raw = torch.tensor(_inv_softplus(getattr(config.weights, n)), dtype=torch.float32)
            self.register_parameter("raw_" + n, nn.Parameter(raw, requires_grad=trainable))

    def value(self, name: str) -> torch.Tensor:
        return F.softplus(getattr(self, "raw_" + name))

    def values(self) -> dict:
        return {n: float(self.value(n).detach()) for n in self.names}

    def weights(self, obs: Observation, dtype: torch.dtype) -> tuple[torch.Tensor, ...]:
        """(λ, η, γ, μ₁, μ₂) for the task: as they are when denoising; under guided upsampling each times its
        multiplier, and λ divided by the factor with ``tv_per_factor`` (TV of an s-times finer grid grows like s for
        the same surface; the quadratic terms do not)."""
        weights = tuple(self.value(n).to(dtype) for n in self.names)
        return _WEIGHT_POLICY[obs.task](self.upsampling, obs.K, weights)

    def forward(self, s: RestorationState, obs: Observation) -> RestorationState:
        K = obs.K
        lam, eta, gamma, mu1, mu2 = self.weights(obs, s.x.dtype)
        residual = obs.y - K(s.x)  # (B,1,h,w)
        maps = _UnitMultipliers() if obs.guidance is None else obs.guidance.maps(
            self.index, s.x, s.q, residual * obs.observed)
        step = LayerStep(state=s, lam=lam, eta=eta, gamma=gamma, mu1=mu1, mu2=mu2, dx=grad(s.x), residual=residual,
                         maps=maps, w=s.w, e=s.e, alpha=s.alpha)
        terms = self.terms[obs.task]
        for term in terms:
            term.split(step, obs)
        matches = s.matches
        if matches is not None and obs.block_matcher.scheduled(self.index):
            matches = obs.block_matcher(s.x, obs, s.q, previous=matches)
        if matches is not None and obs.task in self.match_readers:
            self.match_readers[obs.task](step, matches, obs)
        q, conf, clean = s.q, s.confidence, s.clean
        if obs.task in self.singular_tests:
            q, conf, clean = self.singular_tests[obs.task](obs, s.x, matches)
        system = System(rhs=K.adjoint(q * (obs.y - step.e)), diag=None)
        for term in terms:
            term.system(step, obs, q, system)
        x = self.linear_solver(obs, q, system.mu, system.rhs, s.x, diag=system.diag, layer=self.index)
        return replace(s, x=x, z=step.z, w=step.w, e=step.e, alpha=step.alpha, q=q, confidence=conf,
                       matches=matches, clean=clean)

    def extra_repr(self) -> str:
        return f"index={self.index}, " + ", ".join(f"{k}={v:.3g}" for k, v in self.values().items())


def _denoise_weights(c: UpsamplingConfig, K: Degradation, weights: tuple) -> tuple:
    return weights


def _upsample_weights(c: UpsamplingConfig, K: Degradation, weights: tuple) -> tuple:
    m: LayerMultipliers = c.multipliers
    lam, eta, gamma, mu1, mu2 = (v * float(f) for v, f in zip(weights, (m.lam, m.eta, m.gamma, m.mu1, m.mu2)))
    if c.tv_per_factor:
        lam = lam / K.scale
    return lam, eta, gamma, mu1, mu2


_WEIGHT_POLICY = {"denoise": _denoise_weights, "upsample": _upsample_weights}
