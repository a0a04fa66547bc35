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

import torch
import torch.nn.functional as F
from torch import nn

from .config import LayerMultipliers, RestorerConfig, UpsamplingConfig
from .observation import TASKS, Observation
from .operators import grad
from .stages import LinearSolver
from .state import RestorationState
from .terms import (GuidedPriorTerm, LayerStep, MatchReader, NonlocalTerm, OutlierTerm, Rematch, SingularTest, System,
                    TemporalPriorTerm, TVTerm, ValuePriorTerm)

__all__ = ["UnrolledLayer", "match_steps", "terms_for"]


def _inv_softplus(v: float) -> float:
    v = float(v)
    return v + torch.log(-torch.expm1(torch.tensor(-v))).item() if v < 20 else v


def terms_for(config: RestorerConfig, task: str) -> nn.ModuleList:
    """The terms a layer sums for ``task``, in the order of the sums (the value prior, the guided prior and a stream's
    temporal prior compare the estimate with the observation pixel by pixel: denoising only, the value prior only
    when there are matches)."""
    denoise = task == "denoise"
    clean = _clean_samples(config, task)
    terms: list = [TVTerm(config.weights.isotropic)]
    if denoise and config.guided_prior is not None:
        terms.append(GuidedPriorTerm(config.guided_prior))
    if config.uses("nonlocal"):
        terms.append(NonlocalTerm(clean))
    if _value_prior(config, task) is not None:
        terms.append(ValuePriorTerm())
    if config.uses("outliers"):
        terms.append(OutlierTerm())
    if denoise and config.stream is not None:
        terms.append(TemporalPriorTerm(config.stream))
    return nn.ModuleList(terms)


def _matched(config: RestorerConfig, task: str) -> bool:
    """Whether x⁰ and the layers have matches: for the nonlocal term, or for the singular test (denoising)."""
    return config.uses("nonlocal") or (task == "denoise" and config.uses("singular"))


def _value_prior(config: RestorerConfig, task: str):
    return config.value_prior if task == "denoise" and _matched(config, task) else None


def _clean_samples(config: RestorerConfig, task: str):
    """The clean-sample weights where a gated singular test gives a verdict (denoising), else None."""
    gated = task == "denoise" and config.uses("singular") and config.singular.gate is not None
    return config.clean_samples if gated else None


def match_steps(config: RestorerConfig, task: str, index: int) -> nn.ModuleList:
    """What layer ``index`` does between the split updates and the x-update, for ``task``, in order: match again
    (when scheduled), read the matches (α, the value prior), the singular test (denoising)."""
    steps: list = []
    matched = _matched(config, task)
    if matched and index in config.block_matching.match_layers:
        steps.append(Rematch())
    value = _value_prior(config, task)
    if config.uses("nonlocal") or value is not None:
        steps.append(MatchReader(config.uses("nonlocal"), value, _clean_samples(config, task)))
    if task == "denoise" and config.uses("singular"):
        steps.append(SingularTest(config.singular))
    return nn.ModuleList(steps)


class UnrolledLayer(nn.Module):
    """One iteration; owns its positive parameters λ, η, γ, μ₁, μ₂ (softplus of raw values) and, per task
    (``"denoise"``, ``"upsample"``), its terms (``terms[task]``) and the steps between the split updates and the
    x-update (``steps[task]``: re-matching when scheduled, the read of the matches, the singular test), and the
    solver of the x-update. It matches through the model's :class:`~torch_depth_sr.stages.BlockMatcher`
    (``obs.block_matcher``, which owns the temperature h shared by all layers)."""

    names = ("lam", "eta", "gamma", "mu1", "mu2")

    def __init__(self, config: RestorerConfig, index: int, trainable: bool = False):
        super().__init__()
        self.index = index
        self.upsampling: UpsamplingConfig = config.upsampling  # the weights' policy under guided upsampling
        self.isotropic = config.weights.isotropic  # group TV shrinkage: its threshold's guidance multiplier
        # λ / s under guided upsampling by s with tv_per_factor (TV of an s-times finer grid grows like s)
        self._tv_scale = _per_factor if config.upsampling.tv_per_factor else _as_is
        self.terms = nn.ModuleDict({task: terms_for(config, task) for task in TASKS})
        self.steps = nn.ModuleDict({task: match_steps(config, task, index) for task in TASKS})
        self.linear_solver = LinearSolver(config.solver, index)
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
        return _WEIGHT_POLICY[obs.task](self.upsampling.multipliers, self._tv_scale, obs.K.scale, weights)

    def forward(self, s: RestorationState, obs: Observation) -> RestorationState:
        # the order in which the operations are created is part of the result: the backward pass sums the gradients
        # that reach a tensor in that order (floating point)
        K = obs.K
        lam, eta, gamma, mu1, mu2 = self.weights(obs, s.x.dtype)
        dx = grad(s.x)  # (B,2,H,W)
        residual = obs.y - K(s.x)  # (B,1,h,w)
        tv_threshold = lam / mu1
        maps = obs.guidance.maps(self.index, s.x, s.q, residual, obs.observed)
        step = LayerStep(state=s, lam=lam, eta=eta, gamma=gamma, mu1=mu1, mu2=mu2, dx=dx, residual=residual,
                         maps=maps, tv_threshold=maps.tv_threshold(tv_threshold, self.isotropic),
                         outlier_threshold=maps.outlier_threshold(gamma), w=s.w, e=s.e, alpha=s.alpha,
                         matches=s.matches, q=s.q, confidence=s.confidence, clean=s.clean)
        terms = self.terms[obs.task]
        for term in terms:
            term.split(step, obs)
        for match_step in self.steps[obs.task]:
            match_step(step, obs)
        system = System(rhs=K.adjoint(step.q * (obs.y - step.e)))
        for term in terms:
            term.system(step, obs, system)
        x = self.linear_solver(obs, step.q, system.mu(), system.rhs, s.x, diag=system.diag)
        maps = dict(z=step.z, w=step.w, e=step.e, alpha=step.alpha, q=step.q, confidence=step.confidence)
        if obs.update_region is not None:  # the other pixels keep their state (x already: the solver fixed it)
            maps = {k: _held(obs.update_region, v, getattr(s, k)) for k, v in maps.items()}
        return replace(s, x=x, matches=step.matches, clean=step.clean, **maps)

    def extra_repr(self) -> str:
        return f"index={self.index}, " + ", ".join(f"{k}={v:.3g}" for k, v in self.values().items())


def _held(region: torch.Tensor, new, old):
    """``new`` in ``region``, ``old`` elsewhere (``new`` where there is no ``old``)."""
    if new is None or old is None:
        return new
    return torch.where(region, new, old.to(new))


def _denoise_weights(m: LayerMultipliers, tv_scale, factor: int, weights: tuple) -> tuple:
    return weights


def _upsample_weights(m: LayerMultipliers, tv_scale, factor: int, weights: tuple) -> tuple:
    lam, eta, gamma, mu1, mu2 = (v * float(f) for v, f in zip(weights, (m.lam, m.eta, m.gamma, m.mu1, m.mu2)))
    return tv_scale(lam, factor), eta, gamma, mu1, mu2


def _per_factor(lam: torch.Tensor, factor: int) -> torch.Tensor:
    return lam / factor


def _as_is(lam: torch.Tensor, factor: int) -> torch.Tensor:
    return lam


_WEIGHT_POLICY = {"denoise": _denoise_weights, "upsample": _upsample_weights}
