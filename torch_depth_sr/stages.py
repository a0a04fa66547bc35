"""The stages of an unrolled layer that own a settings group: :class:`BlockMatcher`, :class:`SingularDetector` and
:class:`LinearSolver`, each built once (by :class:`~torch_depth_sr.model.DepthRestorer` and by every
:class:`~torch_depth_sr.layers.UnrolledLayer`) from its group of :mod:`torch_depth_sr.config`.

Each module holds its group as ``settings`` and forwards to a free function that takes the group as an argument
(:func:`run_block_matching`, :func:`singular_test`, :func:`solve_x`): the maths lives once, in the function; the
module only stores the settings and records into the observation's :class:`~torch_depth_sr.state.RunLog` (the
stage's time when timed, the CG iteration counts).
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
from .observation import Observation
from .state import stage

__all__ = [
    "BlockMatcher",
    "LinearSolver",
    "SingularDetector",
    "run_block_matching",
    "singular_test",
    "solve_x",
    "supported_pixels",
]


def run_block_matching(x: torch.Tensor, obs: Observation, q: torch.Tensor, settings: BlockMatchingConfig,
                       temperature: torch.Tensor, color_weight: torch.Tensor,
                       previous: Optional[BlockMatches] = None) -> BlockMatches:
    """Block matching on the current estimate; untrusted pixels masked out of the depth distance.

    The trusted set ``q`` lives on the observation grid, so it masks the distance only when that is the output
    grid (``K = I``). The weights ``softmax(−d/h)`` come with the matches, differentiable in the ``temperature``
    ``h`` when it requires grad; the search itself runs without gradient, and so does the ``color_weight`` ρ. With ``previous`` matches and
    ``settings.rematch == "refine"`` only their offsets and a lattice of the window are re-ranked.
    """
    h, w = x.shape[-2:]
    trust = q.detach() if q.shape[-2:] == (h, w) else None  # Q lives on the observation grid
    window, k = settings.window_and_k()[obs.task]
    # k at most the candidates every pixel has (the image corner's share of the window): a small image, or a
    # small window (the "fast" preset), gets all of them instead of an error
    k = min(k, candidates_everywhere(h, w, window, settings.include_self))
    kw = dict(block_size=settings.block_size, search_window=window, k=k,
              color_weight=color_weight.detach(), temperature=temperature, include_self=settings.include_self)
    if previous is not None and settings.rematch == "refine":
        return refine_matches(x.detach(), previous, obs.rgb, trust, **kw, reach=0, lattice=settings.rematch_lattice)
    return block_match(x.detach(), obs.rgb, trust, **kw)


def singular_test(obs: Observation, x: torch.Tensor, matches: BlockMatches, settings: SingularConfig
                  ) -> tuple[torch.Tensor, torch.Tensor, Optional[torch.Tensor]]:
    """Q, a soft confidence P(x_i) (0 at missing pixels) and the gate's per-sample verdict ``clean`` ((B,1,1,1)
    bool, None without a gate) from the singular-pixel test on the observation grid; ``obs.supported`` (when
    given) are always trusted."""
    c = settings
    clean = None
    with torch.no_grad():
        q, conf = detect_singular(obs.y, x.detach(), obs.observed, matches, sigma_floor=c.sigma_floor,
                                  tau=c.tau, rounds=c.rounds, return_confidence=True)
        if obs.supported is not None:
            q = torch.where(obs.supported, obs.observed.to(q.dtype), q)
            conf = torch.where(obs.supported, torch.maximum(conf, torch.full_like(conf, c.tau)), conf)
        if c.gate is not None:
            # Gate per sample: gross failures (|y − μ| > 2σ_i, i.e. P < e⁻², at least 5 noise σ off) are
            # practically impossible under Gaussian noise; if their share stays below the gate, the sample
            # is taken to have no singular pixels (the test's false alarms sit on true edges and cost accuracy).
            ob = obs.observed.flatten(1)
            gross = (conf.flatten(1) < math.exp(-2.0)).to(ob.dtype) * ob
            share = gross.sum(1) / ob.sum(1).clamp_min(1)  # (B,)
            clean = (share < c.gate).view(-1, 1, 1, 1)
            q = torch.where(clean, obs.observed.to(q.dtype), q)
    return q.to(x.dtype), conf.to(x.dtype), clean


def supported_pixels(y: torch.Tensor, observed: torch.Tensor, grid_step: Optional[torch.Tensor],
                     settings: SingularConfig) -> Optional[torch.Tensor]:
    """Measured pixels with at least ``settings.support`` measured 8-neighbours within the tolerance, or on a
    thin line of agreeing pixels (``settings.line_support``), (B,1,h,w); None when the support rule is off."""
    c = settings
    if c.support <= 0:
        return None
    with torch.no_grad():
        # y is in units of the scale, which is the noise σ̂ unless a floor of the scale policy took over
        tol = torch.as_tensor(c.support_tol, dtype=y.dtype, device=y.device)
        if grid_step is not None:  # neighbours one grid step apart lie on the same surface (slanted, clean)
            tol = torch.maximum(tol, 1.01 * grid_step.to(y))
        supported = neighbour_support(y, observed, tol) >= c.support
        if c.line_support:
            supported = supported | line_support(y, observed, tol)
        return supported


def solve_x(obs: Observation, q: torch.Tensor, mu: torch.Tensor, rhs: torch.Tensor, x0: torch.Tensor,
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
    c, K = settings, obs.K
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
    (``obs.block_matcher``). Times itself as the stage ``"block_matching"``.
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

    def forward(self, x: torch.Tensor, obs: Observation, q: torch.Tensor,
                previous: Optional[BlockMatches] = None) -> BlockMatches:
        """The matches of ``x (B,1,H,W)``, untrusted pixels (``q`` = 0) masked when ``K = I``; see
        :func:`run_block_matching`."""
        with stage(obs.log.timings, "block_matching", x.device):
            return run_block_matching(x, obs, q, self.settings, self.temperature, self.color_weight,
                                      previous=previous)

    def extra_repr(self) -> str:
        s = self.settings
        return (f"block_size={s.block_size}, search_window={s.search_window}, k={s.k}, upsample_search_window="
                f"{s.upsample_search_window}, upsample_k={s.upsample_k}, rematch={s.rematch!r}, "
                f"temperature={float(self.temperature):.3g}, color_weight={float(self.color_weight):.3g}")


class SingularDetector(nn.Module):
    """The singular-pixel test with its neighbour/line support and its per-sample gate (:func:`singular_test`),
    settings :class:`~torch_depth_sr.config.SingularConfig`. On the observation grid (denoising) only. Times itself
    as ``"singular"``."""

    def __init__(self, settings: SingularConfig):
        super().__init__()
        self.settings = settings

    def supported(self, obs: Observation) -> Optional[torch.Tensor]:
        """The pixels every test of this forward trusts (they depend on the observation only); None = no rule."""
        return supported_pixels(obs.y, obs.observed, obs.grid_step, self.settings)

    def forward(self, obs: Observation, x: torch.Tensor,
                matches: BlockMatches) -> tuple[torch.Tensor, torch.Tensor, Optional[torch.Tensor]]:
        """``(Q, confidence, clean)`` of ``x`` against ``obs.y``: (B,1,H,W), (B,1,H,W) and the gate's verdict
        (B,1,1,1) or None."""
        with stage(obs.log.timings, "singular", x.device):
            return singular_test(obs, x, matches, self.settings)

    def extra_repr(self) -> str:
        s = self.settings
        return f"tau={s.tau:.3g}, rounds={s.rounds}, support={s.support}, gate={s.gate}"


class LinearSolver(nn.Module):
    """The x-update: (KᵀQK + diag + μ DᵀD) x = rhs by preconditioned CG (:func:`solve_x`), settings
    :class:`~torch_depth_sr.config.SolverConfig`. Appends the iteration counts to ``obs.log.cg_iterations`` and times
    itself as ``"cg"``."""

    def __init__(self, settings: SolverConfig):
        super().__init__()
        self.settings = settings

    def forward(self, obs: Observation, q: torch.Tensor, mu: torch.Tensor, rhs: torch.Tensor,
                x0: torch.Tensor, diag: Optional[torch.Tensor] = None, layer: Optional[int] = None) -> torch.Tensor:
        """x warm-started at ``x0``; ``layer``: the unrolled layer's index, whose fixed iteration count
        (``settings.iterations(layer)``) applies; None iterates to ``settings.tol``."""
        iterations = None if layer is None else self.settings.iterations(layer)
        with stage(obs.log.timings, "cg", x0.device):
            return solve_x(obs, q, mu, rhs, x0, obs.log.cg_iterations, self.settings, diag=diag,
                           iterations=iterations)

    def extra_repr(self) -> str:
        s = self.settings
        return f"fixed_iters={s.fixed_iters}, tol={s.tol:.3g}, max_iter={s.max_iter}, precondition={s.precondition}"
