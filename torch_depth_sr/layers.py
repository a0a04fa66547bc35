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
Each layer holds the typed settings groups it uses (:mod:`torch_depth_sr.config`), read once when it is built.
"""
from __future__ import annotations

import math
import time
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Iterator, Optional

import torch
import torch.nn.functional as F
from torch import nn

from .block_matching import BlockMatches, block_match, refine_matches
from .config import BlockMatchingConfig, LayerConfig, RestorerConfig, SingularConfig, SolverConfig
from .guidance import PreparedGuidance
from .nonlocal_prior import nonlocal_terms
from .operators import Degradation, grad, grad_adjoint, laplacian
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
def stage(timings: Optional[dict], name: str, device: torch.device) -> Iterator[None]:
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
    """What stays fixed during the unrolled iterations: the observation, the guide and the degradation ``K``."""

    y: torch.Tensor  # (B,1,h,w) normalised observation, 0 where missing
    observed: torch.Tensor  # (B,1,h,w)
    rgb: Optional[torch.Tensor]  # (B,3,H,W)
    K: Degradation  # from the output grid (H,W) to the observation grid (h,w); Identity when they are one
    temperature: torch.Tensor  # scalar, positive
    color_weight: torch.Tensor  # scalar, positive
    prior: Optional[torch.Tensor] = None  # (B,1,H,W) guided estimate that untrusted pixels are pulled to (K = I)
    grid_step: Optional[torch.Tensor] = None  # (B,) quantisation step of y in its normalised units (0 = none)
    fill_confident: Optional[torch.Tensor] = None  # (B,1,h,w) {0,1}: measured, or a hole filled from a clear side
    # (B,1,h,w) bool: measured pixels with enough agreeing measured neighbours (SingularConfig.support), which
    # the singular test always trusts; depends on y only, so the first test computes it (supported_pixels)
    supported: Optional[torch.Tensor] = None
    # (B,1,1,1) bool: samples the last singular test's gate found free of singular pixels (None before a test)
    clean: Optional[torch.Tensor] = None
    # the guidance network with this forward's colour features (RestorerConfig.guidance_net), or None
    guidance: Optional[PreparedGuidance] = None


def run_block_matching(x: torch.Tensor, ctx: RestorationContext, q: torch.Tensor, settings: BlockMatchingConfig,
                       previous: Optional[BlockMatches] = None) -> BlockMatches:
    """Block matching on the current estimate; untrusted pixels masked out of the depth distance.

    The trusted set ``q`` lives on the observation grid, so it masks the distance only when that is the output
    grid (``K = I``). The weights ``softmax(−d/h)`` come with the matches, differentiable in the temperature
    ``h`` when it requires grad; the search itself runs without gradient. With ``previous`` matches and
    ``settings.rematch == "refine"`` only their offsets and a lattice of the window are re-ranked.
    """
    trust = q.detach() if ctx.K.is_identity else None
    kw = dict(block_size=settings.block_size, search_window=settings.search_window, k=settings.k,
              color_weight=ctx.color_weight.detach(), temperature=ctx.temperature, include_self=settings.include_self)
    if previous is not None and settings.rematch == "refine":
        return refine_matches(x.detach(), previous, ctx.rgb, trust, **kw, reach=0, lattice=settings.rematch_lattice)
    return block_match(x.detach(), ctx.rgb, trust, **kw)


def cg_iterations_for(c: RestorerConfig | SolverConfig, index: int) -> Optional[int]:
    """The fixed CG iteration count of layer ``index`` (the schedule's last entry repeats); None = to ``cg_tol``."""
    return (c.solver if isinstance(c, RestorerConfig) else c).iterations(index)


class UnrolledLayer(nn.Module):
    """One iteration; owns its positive parameters λ, η, γ, μ₁, μ₂ (softplus of raw values) and the settings
    groups it uses, taken from ``config`` when it is built: ``terms`` (:class:`~torch_depth_sr.config.LayerConfig`),
    ``matching``, ``value_prior``, ``singular``, ``solver`` and ``upsampling`` (the weights' policy under a
    degradation other than the identity)."""

    names = ("lam", "eta", "gamma", "mu1", "mu2")

    def __init__(self, config: RestorerConfig, index: int, trainable: bool = False):
        super().__init__()
        self.index = index
        self.terms: LayerConfig = config.layer
        self.matching = config.block_matching
        self.value_prior = config.value_prior
        self.singular = config.singular
        self.solver = config.solver
        self.upsampling = config.upsampling
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
        dev = s.x.device
        if matches is not None and self.index in self.matching.match_layers:
            with stage(s.timings, "block_matching", dev):
                matches = run_block_matching(s.x, ctx, s.q, self.matching, previous=matches)
        # the value prior and the singular test compare the estimate with the observation pixel by pixel
        vp = self.value_prior
        value_prior = vp.weight > 0 and K.is_identity and matches is not None
        diag = target = None
        if t.use_nonlocal or value_prior:
            with stage(s.timings, "nonlocal", dev):
                new_alpha, diag, target = nonlocal_terms(
                    s.x, dx if t.use_nonlocal else None, matches, value_weight=vp.weight if value_prior else 0.0,
                    max_var=vp.var, max_offset=vp.offset, plane_ridge=vp.ridge,
                    range_sigma=_range_sigma(vp, ctx.clean))
            if t.use_nonlocal:
                alpha = new_alpha
        if t.use_singular and K.is_identity:
            with stage(s.timings, "singular", dev):
                q, conf = singular_test(ctx, s.x, matches, self.singular)
        beta = prior_weight(ctx, q, t) if ctx.prior is not None else None  # the guided prior's β(1−Q)
        rhs = K.adjoint(q * (ctx.y - e)) + mu1 * grad_adjoint(z)
        if beta is not None:
            rhs = rhs + beta * ctx.prior
        if t.use_nonlocal:
            rhs = rhs + mu2 * grad_adjoint(w + alpha)
        if diag is not None:  # the nonlocal value prior's weights: one more diagonal term
            rhs = rhs + diag * target
            beta = diag if beta is None else beta + diag
        with stage(s.timings, "cg", dev):
            x = solve_x(ctx, q, mu1 + mu2, rhs, s.x, s.cg_iterations, self.solver, diag=beta,
                        iterations=self.solver.iterations(self.index))
        return replace(s, x=x, z=z, w=w, e=e, alpha=alpha, q=q, confidence=conf, matches=matches)

    def extra_repr(self) -> str:
        return f"index={self.index}, " + ", ".join(f"{k}={v:.3g}" for k, v in self.values().items())


def _range_sigma(vp, clean: Optional[torch.Tensor]):
    """The value prior's range σ: ``vp.range``, or per sample ``vp.range_clean`` where the singular gate found
    no outliers (``clean``, (B,1,1,1)); None when off."""
    if vp.range <= 0:
        return None
    if clean is None or vp.range_clean <= 0:
        return vp.range
    return torch.where(clean, float(vp.range_clean), float(vp.range))


def singular_test(ctx: RestorationContext, x: torch.Tensor, matches: BlockMatches,
                  settings: SingularConfig) -> tuple[torch.Tensor, torch.Tensor]:
    """Q and a soft confidence P(x_i) (0 at missing pixels) from the singular-pixel test (``K = I`` only)."""
    c = settings
    with torch.no_grad():
        q, conf = detect_singular(ctx.y, x.detach(), ctx.observed, matches, sigma_floor=c.sigma_floor,
                                  tau=c.tau, rounds=c.rounds, return_confidence=True)
        if c.support > 0:
            if ctx.supported is None:  # depends on y only: computed by the first layer's test, kept for the rest
                ctx.supported = supported_pixels(ctx, c)
            supported = ctx.supported
            q = torch.where(supported, ctx.observed.to(q.dtype), q)
            conf = torch.where(supported, torch.maximum(conf, torch.full_like(conf, c.tau)), conf)
        if c.gate > 0:
            # Gate per sample: gross failures (|y − μ| > 2σ_i, i.e. P < e⁻², at least 5 noise σ off) are
            # practically impossible under Gaussian noise; if their share stays below the gate, the sample
            # is taken to have no singular pixels (the test's false alarms sit on true edges and cost accuracy).
            obs = ctx.observed.flatten(1)
            gross = (conf.flatten(1) < math.exp(-2.0)).to(obs.dtype) * obs
            share = gross.sum(1) / obs.sum(1).clamp_min(1)  # (B,)
            clean = (share < c.gate).view(-1, 1, 1, 1)
            q = torch.where(clean, ctx.observed.to(q.dtype), q)
            ctx.clean = clean
    return q.to(x.dtype), conf.to(x.dtype)


def supported_pixels(ctx: RestorationContext, settings: SingularConfig) -> torch.Tensor:
    """Measured pixels with at least ``settings.support`` measured 8-neighbours within the tolerance, or on a
    thin line of agreeing pixels (``settings.line_support``), (B,1,h,w)."""
    c = settings
    with torch.no_grad():
        # y is in units of the scale, which is the noise σ̂ unless a floor of the scale policy took over
        tol = torch.as_tensor(c.support_tol, dtype=ctx.y.dtype, device=ctx.y.device)
        if ctx.grid_step is not None:  # neighbours one grid step apart lie on the same surface (slanted, clean)
            tol = torch.maximum(tol, 1.01 * ctx.grid_step.to(ctx.y))
        supported = neighbour_support(ctx.y, ctx.observed, tol) >= c.support
        if c.line_support:
            supported = supported | line_support(ctx.y, ctx.observed, tol)
        return supported


def prior_weight(ctx: RestorationContext, q: torch.Tensor, settings: LayerConfig) -> torch.Tensor:
    """β on missing pixels, and on singular ones unless ``settings.prior_on_singular`` is off."""
    untrusted = (1 - q) if settings.prior_on_singular else (1 - ctx.observed)
    return settings.guided_prior * untrusted


def solve_x(ctx: RestorationContext, q: torch.Tensor, mu: torch.Tensor, rhs: torch.Tensor, x0: torch.Tensor,
            log: list, settings: SolverConfig, diag: Optional[torch.Tensor] = None,
            iterations: Optional[int] = None) -> torch.Tensor:
    """Solve (KᵀQK + diag + μ DᵀD) x = rhs by preconditioned CG, warm-started at ``x0``.

    ``diag`` (B,1,H,W) holds the diagonal terms: the guided prior's β(1−Q), the weak pull of untrusted
    (missing or singular) pixels to the colour-guided estimate, and the nonlocal value prior's weights.
    With ``iterations`` CG runs that many iterations (a sample that reaches ``settings.tol`` earlier stops
    changing) and never makes the host wait for the device; with None it iterates until every sample reaches
    ``settings.tol`` (at most ``settings.max_iter``). The preconditioner solves the system with KᵀQK replaced
    by mean(Q)/s² (``s = K.scale``: KᵀK maps a constant image to 1/s² of it). Appends the ``(B,)`` iteration
    counts to ``log``.
    """
    c, K = settings, ctx.K
    q = q.detach()
    beta = diag

    def apply_a(v, mu_=mu):
        av = K.adjoint(q * K(v)) + mu_ * laplacian(v)
        return av if beta is None else av + beta * v

    precond = None
    if c.precondition:
        a = q.flatten(1).mean(1) / (K.scale ** 2)  # (B,)
        if beta is not None:
            a = a + beta.flatten(1).mean(1)
        precond = NeumannPreconditioner(a.detach(), mu.detach())
    fixed = iterations is not None
    res = cg_solve(apply_a, rhs, x0=x0.detach(), precond=precond, tol=c.tol,
                   max_iter=iterations if fixed else c.max_iter, implicit=c.implicit_backward,
                   params=(mu,) if mu.requires_grad else (), early_exit=not fixed, backward_max_iter=c.max_iter)
    log.append(res.iterations)
    return res.x
