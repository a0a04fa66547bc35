"""The stages of an unrolled layer that own a settings group: :class:`BlockMatcher`, :class:`SingularDetector` and
:class:`LinearSolver`, each built once (by :class:`~torch_depth_sr.model.DepthRestorer` and by every
:class:`~torch_depth_sr.layers.UnrolledLayer`) from its group of :mod:`torch_depth_sr.config`.

Each module holds its group as ``settings`` and forwards to a free function that takes the group as an argument
(:func:`run_block_matching`, :func:`singular_test`, :func:`solve_x`): the maths lives once, in the function; the
module only stores the settings and records into the context's :class:`~torch_depth_sr.state.RunLog` (the stage's
time when timed, the CG iteration counts).
"""
from __future__ import annotations

import math
from typing import Optional

import torch
from torch import nn

from .block_matching import BlockMatches, block_match, refine_matches
from .block_matching._common import candidates_everywhere
from .config import BlockMatchingConfig, SingularConfig, SolverConfig
from .operators import laplacian
from .singular import detect_singular, line_support, neighbour_support
from .solvers.dct import NeumannPreconditioner
from .solvers.implicit import cg_solve
from .state import RestorationContext, stage

__all__ = [
    "BlockMatcher",
    "LinearSolver",
    "SingularDetector",
    "run_block_matching",
    "singular_test",
    "solve_x",
    "supported_pixels",
]


def run_block_matching(x: torch.Tensor, ctx: RestorationContext, q: torch.Tensor, settings: BlockMatchingConfig,
                       temperature: torch.Tensor, color_weight: torch.Tensor,
                       previous: Optional[BlockMatches] = None) -> BlockMatches:
    """Block matching on the current estimate; untrusted pixels masked out of the depth distance.

    The trusted set ``q`` lives on the observation grid, so it masks the distance only when that is the output
    grid (``K = I``). The weights ``softmax(−d/h)`` come with the matches, differentiable in the ``temperature``
    ``h`` when it requires grad; the search itself runs without gradient, and so does the ``color_weight`` ρ. With ``previous`` matches and
    ``settings.rematch == "refine"`` only their offsets and a lattice of the window are re-ranked.
    """
    trust = q.detach() if ctx.K.is_identity else None
    h, w = x.shape[-2:]
    window, k = settings.window_and_k(upsampling=not ctx.K.is_identity)
    # k at most the candidates every pixel has (the image corner's share of the window): a small image, or a
    # small window (the "fast" preset), gets all of them instead of an error
    k = min(k, candidates_everywhere(h, w, window, settings.include_self))
    kw = dict(block_size=settings.block_size, search_window=window, k=k,
              color_weight=color_weight.detach(), temperature=temperature, include_self=settings.include_self)
    if previous is not None and settings.rematch == "refine":
        return refine_matches(x.detach(), previous, ctx.rgb, trust, **kw, reach=0, lattice=settings.rematch_lattice)
    return block_match(x.detach(), ctx.rgb, trust, **kw)


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


class BlockMatcher(nn.Module):
    """Block matching of the current estimate (:func:`run_block_matching`) with its
    :class:`~torch_depth_sr.config.BlockMatchingConfig` ``settings`` (block size, search window, k, the layers that
    match again, :meth:`scheduled`, and how) and its two numbers, initialised from the settings: the weight
    temperature ``h``, a parameter (``log_temperature``; learns when ``trainable``: the weights ``softmax(−d/h)``
    are differentiable in it), and the colour weight ``ρ`` of the block distance, a buffer (``log_color_weight``:
    ρ only picks the matches, a discrete choice with no gradient). The model builds one and every layer matches through it
    (``ctx.block_matcher``). Times itself as the stage ``"block_matching"``.
    """

    def __init__(self, settings: BlockMatchingConfig, trainable: bool = False):
        super().__init__()
        self.settings = settings  # its temperature and color_weight are the initial h and ρ
        self.log_temperature = nn.Parameter(torch.tensor(float(settings.temperature)).log(), requires_grad=trainable)
        self.register_buffer("log_color_weight", torch.tensor(max(float(settings.color_weight), 1e-8)).log())

    @property
    def temperature(self) -> torch.Tensor:
        """``h`` as a 0-d tensor (carries the gradient to ``log_temperature``)."""
        return self.log_temperature.exp()

    @property
    def color_weight(self) -> torch.Tensor:
        """``ρ`` as a 0-d tensor."""
        return self.log_color_weight.exp()

    def scheduled(self, index: int) -> bool:
        """Whether layer ``index`` matches again (``settings.match_layers``)."""
        return index in self.settings.match_layers

    def forward(self, x: torch.Tensor, ctx: RestorationContext, q: torch.Tensor,
                previous: Optional[BlockMatches] = None) -> BlockMatches:
        """The matches of ``x (B,1,H,W)``, untrusted pixels (``q`` = 0) masked when ``K = I``; see
        :func:`run_block_matching`."""
        with stage(ctx.log.timings, "block_matching", x.device):
            return run_block_matching(x, ctx, q, self.settings, self.temperature, self.color_weight,
                                      previous=previous)

    def extra_repr(self) -> str:
        s = self.settings
        return (f"block_size={s.block_size}, search_window={s.search_window}, k={s.k}, upsample_search_window="
                f"{s.upsample_search_window}, upsample_k={s.upsample_k}, rematch={s.rematch!r}, "
                f"temperature={float(self.temperature):.3g}, color_weight={float(self.color_weight):.3g}")


class SingularDetector(nn.Module):
    """The singular-pixel test with its neighbour/line support and its per-sample gate (:func:`singular_test`),
    settings :class:`~torch_depth_sr.config.SingularConfig`. ``K = I`` only. Times itself as ``"singular"``."""

    def __init__(self, settings: SingularConfig):
        super().__init__()
        self.settings = settings

    def forward(self, ctx: RestorationContext, x: torch.Tensor,
                matches: BlockMatches) -> tuple[torch.Tensor, torch.Tensor]:
        """``(Q, confidence)`` of ``x`` against ``ctx.y``, both (B,1,H,W); sets ``ctx.supported`` on the first
        test and ``ctx.clean`` (the gate's verdict)."""
        with stage(ctx.log.timings, "singular", x.device):
            return singular_test(ctx, x, matches, self.settings)

    def extra_repr(self) -> str:
        s = self.settings
        return f"tau={s.tau:.3g}, rounds={s.rounds}, support={s.support}, gate={s.gate:.3g}"


class LinearSolver(nn.Module):
    """The x-update: (KᵀQK + diag + μ DᵀD) x = rhs by preconditioned CG (:func:`solve_x`), settings
    :class:`~torch_depth_sr.config.SolverConfig`. Appends the iteration counts to ``ctx.log.cg_iterations`` and times
    itself as ``"cg"``."""

    def __init__(self, settings: SolverConfig):
        super().__init__()
        self.settings = settings

    def forward(self, ctx: RestorationContext, q: torch.Tensor, mu: torch.Tensor, rhs: torch.Tensor,
                x0: torch.Tensor, diag: Optional[torch.Tensor] = None, layer: Optional[int] = None) -> torch.Tensor:
        """x warm-started at ``x0``; ``layer``: the unrolled layer's index, whose fixed iteration count
        (``settings.iterations(layer)``) applies; None iterates to ``settings.tol``."""
        iterations = None if layer is None else self.settings.iterations(layer)
        with stage(ctx.log.timings, "cg", x0.device):
            return solve_x(ctx, q, mu, rhs, x0, ctx.log.cg_iterations, self.settings, diag=diag,
                           iterations=iterations)

    def extra_repr(self) -> str:
        s = self.settings
        return f"fixed_iters={s.fixed_iters}, tol={s.tol:.3g}, max_iter={s.max_iter}, precondition={s.precondition}"
