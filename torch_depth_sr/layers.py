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

Terms switched off in the config drop out of both the updates and the linear system, so the
ablations (TV only, TV + nonlocal) run through this same code. ``K`` is the
:class:`~torch_depth_sr.operators.Degradation` the model builds for the task and hands over in the
:class:`RestorationContext`; the layer applies it and its adjoint and never asks which task it is.
Each layer holds the typed settings groups it reads itself (:mod:`torch_depth_sr.config`) and the stages that own
theirs (:mod:`torch_depth_sr.stages`: block matcher, singular detector, linear solver), built once with the layer.
The moved names (:class:`RestorationState`, :class:`RestorationContext`, :func:`stage` from
:mod:`torch_depth_sr.state`; the stages' functions from :mod:`torch_depth_sr.stages`) are importable from here too.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Optional

import torch
import torch.nn.functional as F
from torch import nn

from .config import LayerConfig, RestorerConfig, SolverConfig, ValuePriorConfig
from .nonlocal_prior import nonlocal_terms
from .operators import grad, grad_adjoint
from .shrinkage import group_soft_threshold, soft_threshold
from .stages import (LinearSolver, SingularDetector, run_block_matching, singular_test, solve_x,
                     supported_pixels)
from .state import RestorationContext, RestorationState, RunLog, stage

__all__ = [
    "RestorationState",
    "RunLog",
    "stage",
    "RestorationContext",
    "run_block_matching",
    "cg_iterations_for",
    "UnrolledLayer",
    "singular_test",
    "supported_pixels",
    "prior_weight",
    "solve_x",
]


def _inv_softplus(v: float) -> float:
    v = float(v)
    return v + torch.log(-torch.expm1(torch.tensor(-v))).item() if v < 20 else v


def cg_iterations_for(c: RestorerConfig | SolverConfig, index: int) -> Optional[int]:
    """The fixed CG iteration count of layer ``index`` (the schedule's last entry repeats); None = to ``cg_tol``."""
    return (c.solver if isinstance(c, RestorerConfig) else c).iterations(index)


class UnrolledLayer(nn.Module):
    """One iteration; owns its positive parameters λ, η, γ, μ₁, μ₂ (softplus of raw values), the settings groups
    it reads itself, ``terms`` (:class:`~torch_depth_sr.config.LayerConfig`), ``value_prior`` and ``upsampling`` (the
    weights' policy under a degradation other than the identity), and its stages, each holding its group as
    ``settings``: ``singular_detector`` (:class:`~torch_depth_sr.stages.SingularDetector`) and ``linear_solver``
    (:class:`~torch_depth_sr.stages.LinearSolver`). All are taken from ``config`` when the layer is built. It
    matches through the model's :class:`~torch_depth_sr.stages.BlockMatcher` (``ctx.block_matcher``, which owns the
    temperature h shared by all layers) when that schedules this layer."""

    names = ("lam", "eta", "gamma", "mu1", "mu2")

    def __init__(self, config: RestorerConfig, index: int, trainable: bool = False):
        super().__init__()
        self.index = index
        self.terms: LayerConfig = config.layer
        self.value_prior: ValuePriorConfig = config.value_prior
        self.upsampling = config.upsampling
        self.singular_detector = SingularDetector(config.singular)
        self.linear_solver = LinearSolver(config.solver)
        for n in self.names:
            raw = torch.tensor(_inv_softplus(getattr(self.terms, n)), dtype=torch.float32)
            self.register_parameter("raw_" + n, nn.Parameter(raw, requires_grad=trainable))

    def value(self, name: str) -> torch.Tensor:
        return F.softplus(getattr(self, "raw_" + name))

    def values(self) -> dict:
        return {n: float(self.value(n).detach()) for n in self.names}

    def forward(self, s: RestorationState, ctx: RestorationContext) -> RestorationState:
        t, K = self.terms, ctx.K
        dt = s.x.dtype
        lam, eta, gamma, mu1, mu2 = self.upsampling.layer_weights(K, *(self.value(n).to(dt) for n in self.names))
        shrink = group_soft_threshold if t.isotropic else soft_threshold
        dx = grad(s.x)  # (B,2,H,W)
        residual = ctx.y - K(s.x)  # (B,1,h,w)
        tv_thr, nl_thr, gamma_thr = lam / mu1, None, gamma
        if ctx.guidance is not None:  # per-pixel multipliers of the thresholds (issue 14)
            maps = ctx.guidance.maps(self.index, s.x, s.q, residual * ctx.observed)
            # the group (isotropic) threshold takes the geometric mean of the two directions' multipliers
            tv_thr = tv_thr * (maps.tv.prod(1, keepdim=True).sqrt() if t.isotropic else maps.tv)
            gamma_thr = gamma * maps.outlier
        z = shrink(dx, tv_thr)
        if t.use_nonlocal:
            if ctx.clean is not None and t.eta_clean != 1.0:  # samples without outliers: α matters less
                eta = eta * torch.where(ctx.clean, torch.full_like(eta, t.eta_clean), torch.ones_like(eta))
            nl_thr = eta / mu2 if ctx.guidance is None else eta / mu2 * maps.nonlocal_
            w = soft_threshold(dx - s.alpha, nl_thr)
        else:
            w, mu2 = s.w, torch.zeros_like(mu2)
        e = s.q * soft_threshold(residual, gamma_thr) if t.use_outliers else s.e
        matches, alpha, q, conf = s.matches, s.alpha, s.q, s.confidence
        if matches is not None and ctx.block_matcher.scheduled(self.index):
            matches = ctx.block_matcher(s.x, ctx, s.q, previous=matches)
        # the value prior and the singular test compare the estimate with the observation pixel by pixel
        vp = self.value_prior
        value_prior = vp.weight > 0 and K.is_identity and matches is not None
        diag = target = None
        if t.use_nonlocal or value_prior:
            with stage(ctx.log.timings, "nonlocal", s.x.device):
                new_alpha, diag, target = nonlocal_terms(
                    s.x, dx if t.use_nonlocal else None, matches, value_weight=vp.weight if value_prior else 0.0,
                    max_var=vp.var, max_offset=vp.offset, plane_ridge=vp.ridge,
                    range_sigma=_range_sigma(vp, ctx.clean))
            if t.use_nonlocal:
                alpha = new_alpha
            if diag is not None and ctx.clean is not None and vp.weight_clean > 0 and vp.weight_clean != vp.weight:
                diag = diag * torch.where(ctx.clean, vp.weight_clean / vp.weight, 1.0).to(diag.dtype)
        if t.use_singular and K.is_identity:
            q, conf = self.singular_detector(ctx, s.x, matches)
        beta = prior_weight(ctx, q, t) if ctx.prior is not None else None  # the guided prior's β(1−Q)
        rhs = K.adjoint(q * (ctx.y - e)) + mu1 * grad_adjoint(z)
        if beta is not None:
            rhs = rhs + beta * ctx.prior
        if t.use_nonlocal:
            rhs = rhs + mu2 * grad_adjoint(w + alpha)
        if diag is not None:  # the nonlocal value prior's weights: one more diagonal term
            rhs = rhs + diag * target
            beta = diag if beta is None else beta + diag
        x = self.linear_solver(ctx, q, mu1 + mu2, rhs, s.x, diag=beta, layer=self.index)
        return replace(s, x=x, z=z, w=w, e=e, alpha=alpha, q=q, confidence=conf, matches=matches)

    def extra_repr(self) -> str:
        return f"index={self.index}, " + ", ".join(f"{k}={v:.3g}" for k, v in self.values().items())


def _range_sigma(vp: ValuePriorConfig, clean: Optional[torch.Tensor]) -> Optional[float | torch.Tensor]:
    """The value prior's range σ: ``vp.range``, or per sample ``vp.range_clean`` where the singular gate found
    no outliers (``clean``, (B,1,1,1)); None when off."""
    if vp.range <= 0:
        return None
    if clean is None or vp.range_clean <= 0:
        return vp.range
    return torch.where(clean, float(vp.range_clean), float(vp.range))


def prior_weight(ctx: RestorationContext, q: torch.Tensor, settings: LayerConfig) -> torch.Tensor:
    """β on missing pixels, and on singular ones unless ``settings.prior_on_singular`` is off."""
    untrusted = (1 - q) if settings.prior_on_singular else (1 - ctx.observed)
    return settings.guided_prior * untrusted
