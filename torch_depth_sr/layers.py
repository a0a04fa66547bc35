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
ablations (TV only, TV + nonlocal) run through this same code.
"""
from __future__ import annotations

import math
import time
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Optional, Sequence

import torch
import torch.nn.functional as F
from torch import nn

from .block_matching import BlockMatches, block_match, refine_matches
from .config import RestorerConfig
from .nonlocal_prior import nonlocal_terms
from .operators import LinearOperator, grad, grad_adjoint, laplacian
from .shrinkage import group_soft_threshold, soft_threshold
from .singular import detect_singular, line_support, neighbour_support
from .solvers.dct import NeumannPreconditioner
from .solvers.implicit import cg_solve

__all__ = [
    "RestorationState",
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


@dataclass
class RestorationState:
    """Variables carried from layer to layer (all in normalised units)."""

    x: torch.Tensor  # (B,1,H,W) estimate on the output grid
    z: torch.Tensor  # (B,2,H,W)
    w: torch.Tensor  # (B,2,H,W)
    e: torch.Tensor  # (B,1,h,w) outliers on the observation grid
    alpha: torch.Tensor  # (B,2,H,W)
    q: torch.Tensor  # (B,1,h,w) {0,1} trusted pixels
    confidence: torch.Tensor  # (B,1,h,w) in [0,1]
    matches: Optional[BlockMatches]  # weights included (differentiable in the temperature)
    cg_iterations: list  # per layer, a (B,) int64 tensor of CG iterations (read only when reported)
    timings: Optional[dict] = None  # seconds per stage, accumulated over layers; None = not timed


@contextmanager
def stage(timings: Optional[dict], name: str, device: torch.device):
    """Accumulate the wall time of a stage into ``timings``; with ``timings=None`` nothing is timed.

    Timing synchronises CUDA before and after the stage (so the time is real), which a forward that is not
    timed must not do: the host would wait for the device at every stage.
    """
    with torch.profiler.record_function(f"stage:{name}"):  # a no-op unless a profiler is running
        if timings is None:
            yield
            return
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        t0 = time.perf_counter()
        yield
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        timings[name] = timings.get(name, 0.0) + time.perf_counter() - t0


@dataclass
class RestorationContext:
    """What stays fixed during the unrolled iterations."""

    y: torch.Tensor  # (B,1,h,w) normalised observation, 0 where missing
    observed: torch.Tensor  # (B,1,h,w)
    rgb: Optional[torch.Tensor]  # (B,3,H,W)
    factor: int  # K = identity (1) or area downsampling by `factor`
    config: RestorerConfig
    temperature: torch.Tensor  # scalar, positive
    color_weight: torch.Tensor  # scalar, positive
    prior: Optional[torch.Tensor] = None  # (B,1,H,W) guided estimate that untrusted pixels are pulled to (K = I)
    grid_step: Optional[torch.Tensor] = None  # (B,) quantisation step of y in its normalised units (0 = none)
    fill_confident: Optional[torch.Tensor] = None  # (B,1,h,w) {0,1}: measured, or a hole filled from a clear side
    # (B,1,h,w) bool: measured pixels with enough agreeing measured neighbours (config.singular_support), which
    # the singular test always trusts; depends on y only, so the first test computes it (supported_pixels)
    supported: Optional[torch.Tensor] = None

    degradation: Optional[LinearOperator] = None  # K when factor > 1 (None: area averaging)

    def K(self, x):
        if self.factor == 1:
            return x
        return F.avg_pool2d(x, self.factor) if self.degradation is None else self.degradation(x)

    def Kt(self, v):
        if self.factor == 1:
            return v
        if self.degradation is not None:
            return self.degradation.adjoint(v)
        s = self.factor
        return F.interpolate(v, scale_factor=s, mode="nearest") / (s * s)


def run_block_matching(x: torch.Tensor, ctx: RestorationContext, q: torch.Tensor,
                       previous: Optional[BlockMatches] = None) -> BlockMatches:
    """Block matching on the current estimate; untrusted pixels masked out of the depth distance.

    The weights ``softmax(−d/h)`` come with the matches, differentiable in the temperature ``h`` when it
    requires grad; the search itself runs without gradient. With ``previous`` matches and
    ``config.rematch == "refine"`` only their offsets and a lattice of the window are re-ranked.
    """
    c = ctx.config
    trust = q.detach() if ctx.factor == 1 else None
    kw = dict(block_size=c.block_size, search_window=c.search_window, k=c.k,
              color_weight=ctx.color_weight.detach(), temperature=ctx.temperature, include_self=c.include_self)
    if previous is not None and c.rematch == "refine":
        return refine_matches(x.detach(), previous, ctx.rgb, trust, **kw, reach=0, lattice=c.rematch_lattice)
    return block_match(x.detach(), ctx.rgb, trust, **kw)


def cg_iterations_for(c: RestorerConfig, index: int) -> Optional[int]:
    """The fixed CG iteration count of layer ``index`` (the schedule's last entry repeats); None = to ``cg_tol``."""
    sched: Sequence[int] = c.cg_fixed_iters
    if not sched:
        return None
    return int(sched[min(index, len(sched) - 1)])


class UnrolledLayer(nn.Module):
    """One iteration; owns its positive parameters λ, η, γ, μ₁, μ₂ (softplus of raw values)."""

    names = ("lam", "eta", "gamma", "mu1", "mu2")

    def __init__(self, config: RestorerConfig, index: int, trainable: bool = False):
        super().__init__()
        self.index = index
        for n in self.names:
            raw = torch.tensor(_inv_softplus(getattr(config, n)), dtype=torch.float32)
            self.register_parameter("raw_" + n, nn.Parameter(raw, requires_grad=trainable))

    def value(self, name: str) -> torch.Tensor:
        return F.softplus(getattr(self, "raw_" + name))

    def values(self) -> dict:
        return {n: float(self.value(n).detach()) for n in self.names}

    def forward(self, s: RestorationState, ctx: RestorationContext) -> RestorationState:
        c = ctx.config
        dt = s.x.dtype
        lam, eta, gamma, mu1, mu2 = (self.value(n).to(dt) for n in self.names)
        if ctx.factor > 1:
            scale = c.upsample_scale
            lam, eta, gamma, mu1, mu2 = (v * float(scale.get(n, 1.0))
                                         for n, v in zip(self.names, (lam, eta, gamma, mu1, mu2)))
            if c.upsample_tv_per_factor:
                lam = lam / ctx.factor
        shrink = group_soft_threshold if c.isotropic else soft_threshold
        dx = grad(s.x)  # (B,2,H,W)
        z = shrink(dx, lam / mu1)
        if c.use_nonlocal:
            w = soft_threshold(dx - s.alpha, eta / mu2)
        else:
            w, mu2 = s.w, torch.zeros_like(mu2)
        e = s.q * soft_threshold(ctx.y - ctx.K(s.x), gamma) if c.use_outliers else s.e
        matches, alpha, q, conf = s.matches, s.alpha, s.q, s.confidence
        dev = s.x.device
        if matches is not None and self.index in c.match_layers:
            with stage(s.timings, "block_matching", dev):
                matches = run_block_matching(s.x, ctx, s.q, previous=matches)
        value_prior = c.nl_value_weight > 0 and ctx.factor == 1 and matches is not None
        diag = target = None
        if c.use_nonlocal or value_prior:
            with stage(s.timings, "nonlocal", dev):
                new_alpha, diag, target = nonlocal_terms(
                    s.x, dx if c.use_nonlocal else None, matches, value_weight=c.nl_value_weight if value_prior else 0.0,
                    max_var=c.nl_value_var, max_offset=c.nl_value_offset, plane_ridge=c.nl_value_ridge,
                    range_sigma=c.nl_value_range if c.nl_value_range > 0 else None)
            if c.use_nonlocal:
                alpha = new_alpha
        if c.use_singular and ctx.factor == 1:
            with stage(s.timings, "singular", dev):
                q, conf = singular_test(ctx, s.x, matches)
        rhs = ctx.Kt(q * (ctx.y - e)) + mu1 * grad_adjoint(z)
        if ctx.prior is not None:
            rhs = rhs + prior_weight(ctx, q) * ctx.prior
        if c.use_nonlocal:
            rhs = rhs + mu2 * grad_adjoint(w + alpha)
        if diag is not None:
            rhs = rhs + diag * target
        with stage(s.timings, "cg", dev):
            x = solve_x(ctx, q, mu1 + mu2, rhs, s.x, s.cg_iterations, diag=diag,
                        iterations=cg_iterations_for(c, self.index))
        return replace(s, x=x, z=z, w=w, e=e, alpha=alpha, q=q, confidence=conf, matches=matches)

    def extra_repr(self) -> str:
        return f"index={self.index}, " + ", ".join(f"{k}={v:.3g}" for k, v in self.values().items())


def singular_test(ctx: RestorationContext, x: torch.Tensor, matches: BlockMatches):
    """Q and a soft confidence P(x_i) (0 at missing pixels) from the singular-pixel test."""
    c = ctx.config
    with torch.no_grad():
        q, conf = detect_singular(ctx.y, x.detach(), ctx.observed, matches, sigma_floor=c.singular_sigma_floor,
                                  tau=c.singular_tau, rounds=c.singular_rounds, return_confidence=True)
        if c.singular_support > 0:
            if ctx.supported is None:  # depends on y only: computed by the first layer's test, kept for the rest
                ctx.supported = supported_pixels(ctx)
            supported = ctx.supported
            q = torch.where(supported, ctx.observed.to(q.dtype), q)
            conf = torch.where(supported, torch.maximum(conf, torch.full_like(conf, c.singular_tau)), conf)
        if c.singular_gate > 0:
            # Gate per sample: gross failures (|y − μ| > 2σ_i, i.e. P < e⁻², at least 5 noise σ off) are
            # practically impossible under Gaussian noise; if their share stays below the gate, the sample
            # is taken to have no singular pixels (the test's false alarms sit on true edges and cost accuracy).
            obs = ctx.observed.flatten(1)
            gross = (conf.flatten(1) < math.exp(-2.0)).to(obs.dtype) * obs
            share = gross.sum(1) / obs.sum(1).clamp_min(1)  # (B,)
            clean = (share < c.singular_gate).view(-1, 1, 1, 1)
            q = torch.where(clean, ctx.observed.to(q.dtype), q)
    return q.to(x.dtype), conf.to(x.dtype)


def supported_pixels(ctx: RestorationContext) -> torch.Tensor:
    """Measured pixels with at least ``singular_support`` measured 8-neighbours within the tolerance, or on a
    thin line of agreeing pixels (``singular_line_support``), (B,1,h,w)."""
    c = ctx.config
    with torch.no_grad():
        # y is in units of the scale, which is the noise σ̂ unless a floor of the scale policy took over
        tol = torch.as_tensor(c.singular_support_tol, dtype=ctx.y.dtype, device=ctx.y.device)
        if ctx.grid_step is not None:  # neighbours one grid step apart lie on the same surface (slanted, clean)
            tol = torch.maximum(tol, 1.01 * ctx.grid_step.to(ctx.y))
        supported = neighbour_support(ctx.y, ctx.observed, tol) >= c.singular_support
        if c.singular_line_support:
            supported = supported | line_support(ctx.y, ctx.observed, tol)
        return supported


def prior_weight(ctx: RestorationContext, q: torch.Tensor) -> torch.Tensor:
    """β on missing pixels, and on singular ones unless ``config.prior_on_singular`` is off."""
    c = ctx.config
    untrusted = (1 - q) if c.prior_on_singular else (1 - ctx.observed)
    return c.guided_prior * untrusted


def solve_x(ctx: RestorationContext, q: torch.Tensor, mu: torch.Tensor, rhs: torch.Tensor, x0: torch.Tensor,
            log: list, diag: Optional[torch.Tensor] = None, iterations: Optional[int] = None) -> torch.Tensor:
    """Solve (KᵀQK + β(1−Q) + μ DᵀD) x = rhs by preconditioned CG, warm-started at ``x0``.

    β(1−Q) is the weak pull of untrusted (missing or singular) pixels to the colour-guided estimate
    (``config.guided_prior``; absent when there is no guide or K ≠ I). With ``iterations`` CG runs that many
    iterations (a sample that reaches ``cg_tol`` earlier stops changing) and never makes the host wait for
    the device; with None it iterates until every sample reaches ``cg_tol`` (at most ``cg_max_iter``).
    Appends the ``(B,)`` iteration counts to ``log``.
    """
    c = ctx.config
    q = q.detach()

    beta = prior_weight(ctx, q) if ctx.prior is not None else None
    if diag is not None:  # the nonlocal value prior's weights: one more diagonal term
        beta = diag if beta is None else beta + diag

    def apply_a(v, mu_=mu):
        av = ctx.Kt(q * ctx.K(v)) + mu_ * laplacian(v)
        return av if beta is None else av + beta * v

    precond = None
    if c.precondition:
        a = q.flatten(1).mean(1) / (ctx.factor ** 2)  # (B,)
        if beta is not None:
            a = a + beta.flatten(1).mean(1)
        precond = NeumannPreconditioner(a.detach(), mu.detach())
    fixed = iterations is not None
    res = cg_solve(apply_a, rhs, x0=x0.detach(), precond=precond, tol=c.cg_tol,
                   max_iter=iterations if fixed else c.cg_max_iter, implicit=c.implicit_backward,
                   params=(mu,) if mu.requires_grad else (), early_exit=not fixed, backward_max_iter=c.cg_max_iter)
    log.append(res.iterations)
    return res.x
