"""The stages of an unrolled layer that own a settings group: :class:`BlockMatcher`, :class:`SingularDetector` and
:class:`LinearSolver`, each built once (by :class:`~torch_depth_sr.model.DepthRestorer` and by every
:class:`~torch_depth_sr.layers.UnrolledLayer`) from its group of :mod:`torch_depth_sr.config`.

Each module holds its group as ``settings``; what the settings choose (exact or refined re-matching, the support
rules and the gate of the singular test, the preconditioner, the CG schedule) is chosen once, when the module is
built, so a forward runs without asking. The modules record into the observation's
:class:`~torch_depth_sr.state.RunLog` (the stage's time when timed, the CG iteration counts).
"""
from __future__ import annotations

import math
from typing import Callable, Optional

import torch
from torch import nn

from .block_matching import BlockMatches, block_match, block_match_at, refine_matches
from .block_matching._common import candidates_everywhere
from .config import BlockMatchingConfig, SingularConfig, SolverConfig
from .native import host_path, on_device
from .observation import Observation
from .operators import laplacian, laplacian_diagonal
from .singular import detect_singular, neighbour_support, supported_or_line
from .solvers.dct import NeumannPreconditioner
from .solvers.implicit import cg_solve
from .state import stage

__all__ = ["BlockMatcher", "LinearSolver", "SingularDetector", "supported_pixels"]


# ---- block matching ---------------------------------------------------------------------------------
def _search(x: torch.Tensor, obs: Observation, trust: Optional[torch.Tensor], previous: Optional[BlockMatches],
            settings: BlockMatchingConfig, kw: dict) -> BlockMatches:
    """The exact search of the whole window."""
    return block_match(x.detach(), obs.rgb, trust, **kw)


def _refine(x: torch.Tensor, obs: Observation, trust: Optional[torch.Tensor], previous: Optional[BlockMatches],
            settings: BlockMatchingConfig, kw: dict) -> BlockMatches:
    """The previous matches and the offsets of a step-``rematch_lattice`` lattice of the window, re-ranked exactly."""
    return refine_matches(x.detach(), previous, obs.rgb, trust, **kw, reach=0, lattice=settings.rematch_lattice)


_REMATCH = {"exact": _search, "refine": _refine}


class BlockMatcher(nn.Module):
    """Block matching of the current estimate with its :class:`~torch_depth_sr.config.BlockMatchingConfig`
    ``settings`` (block size, search window, k, the layers that match again, :meth:`scheduled`, and how) and its
    two numbers, initialised from the settings: the weight temperature ``h``, a parameter (``log_temperature``;
    learns when ``trainable``: the weights ``softmax(−d/h)`` are differentiable in it), and the colour weight ``ρ``
    of the block distance, a buffer (``log_color_weight``: ρ only picks the matches, a discrete choice with no
    gradient). The model builds one and every layer matches through it (``obs.block_matcher``). Times itself as the
    stage ``"block_matching"``.

    The trusted set ``q`` lives on the observation grid, so it masks the depth distance only when that is the output
    grid (denoising). The search itself runs without gradient.
    """

    def __init__(self, settings: BlockMatchingConfig, trainable: bool = False):
        super().__init__()
        self.settings = settings  # its temperature and color_weight are the initial h and ρ
        self.log_temperature = nn.Parameter(torch.tensor(float(settings.temperature)).log(), requires_grad=trainable)
        self.register_buffer("log_color_weight", torch.tensor(max(float(settings.color_weight), 1e-8)).log())
        self._rematch = _REMATCH[settings.rematch]

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

    def _trust_and_window(self, x: torch.Tensor, obs: Observation, q: torch.Tensor):
        """``(trust, window, k)`` of a search of ``x``: Q as the trust map where it lies on ``x``'s grid (Q lives on
        the observation grid), the task's search window and k."""
        trust = q.detach() if q.shape[-2:] == x.shape[-2:] else None
        return (trust, *self.settings.window_and_k()[obs.task])

    def _run(self, search: Callable, x: torch.Tensor, obs: Observation, q: torch.Tensor,
             previous: Optional[BlockMatches]) -> BlockMatches:
        s = self.settings
        h, w = x.shape[-2:]
        trust, window, k = self._trust_and_window(x, obs, q)
        # k at most the candidates every pixel has (the image corner's share of the window): a small image, or a
        # small window (the "fast" preset), gets all of them instead of an error
        k = min(k, candidates_everywhere(h, w, window, s.include_self))
        kw = dict(block_size=s.block_size, search_window=window, k=k, color_weight=self.color_weight.detach(),
                  temperature=self.temperature, include_self=s.include_self)
        with stage(obs.log.timings, "block_matching", x.device):
            return search(x, obs, trust, previous, s, kw)

    def forward(self, x: torch.Tensor, obs: Observation, q: torch.Tensor) -> BlockMatches:
        """The matches of ``x (B,1,H,W)`` by the exact search, untrusted pixels (``q`` = 0) masked when denoising."""
        return self._run(_search, x, obs, q, None)

    def rematch(self, x: torch.Tensor, obs: Observation, q: torch.Tensor, previous: BlockMatches) -> BlockMatches:
        """The matches of ``x`` in a scheduled layer, by ``settings.rematch`` (``"refine"`` starts from
        ``previous``)."""
        return self._run(self._rematch, x, obs, q, previous)

    def search_at(self, x: torch.Tensor, obs: Observation, q: torch.Tensor, where: torch.Tensor,
                  dist: torch.Tensor, index: torch.Tensor) -> bool:
        """:meth:`forward`'s matches at the pixels ``where`` alone, written into ``dist`` and ``index`` in place
        (:func:`~torch_depth_sr.block_matching.block_match_at`: the whole image's, bit for bit); False, nothing
        written, where that search does not run (off the CPU's numba kernel)."""
        s = self.settings
        trust, window, _ = self._trust_and_window(x, obs, q)
        with stage(obs.log.timings, "block_matching", x.device):
            return block_match_at(x.detach(), obs.rgb, trust, where, dist, index, block_size=s.block_size,
                                  search_window=window, color_weight=self.color_weight.detach(),
                                  include_self=s.include_self)

    def extra_repr(self) -> str:
        s = self.settings
        return (f"block_size={s.block_size}, search_window={s.search_window}, k={s.k}, upsample_search_window="
                f"{s.upsample_search_window}, upsample_k={s.upsample_k}, rematch={s.rematch!r}, "
                f"temperature={float(self.temperature):.3g}, color_weight={float(self.color_weight):.3g}")


# ---- the singular test ------------------------------------------------------------------------------
def _neighbours(y: torch.Tensor, observed: torch.Tensor, tol: torch.Tensor, c: SingularConfig) -> torch.Tensor:
    return neighbour_support(y, observed, tol) >= c.support


def _neighbours_or_line(y: torch.Tensor, observed: torch.Tensor, tol: torch.Tensor, c: SingularConfig) -> torch.Tensor:
    return supported_or_line(y, observed, tol, c.support)


_SUPPORT_RULES = {False: _neighbours, True: _neighbours_or_line}  # by SingularConfig.line_support


def supported_pixels(y: torch.Tensor, observed: torch.Tensor, grid_step: torch.Tensor,
                     settings: SingularConfig) -> torch.Tensor:
    """Measured pixels with at least ``settings.support`` measured 8-neighbours within the tolerance, or on a
    thin line of agreeing pixels (``settings.line_support``), (B,1,h,w) bool."""
    rule = _SUPPORT_RULES[settings.line_support]
    with torch.no_grad():
        # y is in units of the scale, which is the noise σ̂ unless a floor of the scale policy took over
        tol = on_device(settings.support_tol, y.dtype, y.device)
        # neighbours one grid step apart lie on the same surface (slanted, clean)
        tol = torch.maximum(tol, 1.01 * grid_step.to(y))
        return rule(y, observed, tol, settings)


def _no_support(obs: Observation, settings: SingularConfig) -> None:
    return None


def _support(obs: Observation, settings: SingularConfig) -> torch.Tensor:
    return supported_pixels(obs.y, obs.observed, obs.grid_step, settings)


def _trust_supported(obs: Observation, q: torch.Tensor, conf: torch.Tensor, c: SingularConfig):
    """Supported pixels (``obs.supported``) stay trusted, with at least the confidence τ."""
    q = torch.where(obs.supported, obs.observed.to(q.dtype), q)
    conf = torch.where(obs.supported, torch.maximum(conf, torch.full_like(conf, c.tau)), conf)
    return q, conf


def _as_tested(obs: Observation, q: torch.Tensor, conf: torch.Tensor, c: SingularConfig):
    return q, conf


def _gate(obs: Observation, q: torch.Tensor, conf: torch.Tensor, c: SingularConfig):
    """Gate per sample: gross failures (|y − μ| > 2σ_i, i.e. P < e⁻², at least 5 noise σ off) are practically
    impossible under Gaussian noise; if their share stays below the gate, the sample is taken to have no singular
    pixels (the test's false alarms sit on true edges and cost accuracy): Q = measured, and ``clean`` says so.

    With ``obs.gate_region`` the share within that region must stay below the gate too, where the region holds at
    least 1/gate measured pixels (fewer cannot tell a share below the gate from none). A stream's static pixels see
    the mean of their run, which has already dropped or held out the past's singular readings: counted with the
    others, they diluted the flying pixels at a mover's edges below the gate at 640×480 and switched the edge steps
    off for the whole frame (docs/measurements/issue28-stream/twenty-third-stop/)."""
    ob = obs.observed.flatten(1)
    gross = (conf.flatten(1) < math.exp(-2.0)).to(ob.dtype) * ob
    share = gross.sum(1) / ob.sum(1).clamp_min(1)  # (B,)
    clean = share < c.gate
    if obs.gate_region is not None:
        region = ob * obs.gate_region.flatten(1).to(ob.dtype)
        n = region.sum(1)
        clean = clean & ((n < 1.0 / c.gate) | ((gross * region).sum(1) / n.clamp_min(1) < c.gate))
    clean = clean.view(-1, 1, 1, 1)
    return torch.where(clean, obs.observed.to(q.dtype), q), clean


def _no_gate(obs: Observation, q: torch.Tensor, conf: torch.Tensor, c: SingularConfig):
    return q, None


def _distrust(obs: Observation, q: torch.Tensor) -> torch.Tensor:
    """Q = 0 at the measurements ``obs.untrusted`` names (a stream's: its single measurements without support)."""
    return q if obs.untrusted is None else torch.where(obs.untrusted, torch.zeros_like(q), q)


class SingularDetector(nn.Module):
    """The singular-pixel test (:func:`~torch_depth_sr.singular.detect_singular`) with its neighbour/line support and
    its per-sample gate, settings :class:`~torch_depth_sr.config.SingularConfig`. On the observation grid (denoising)
    only. Times itself as ``"singular"``."""

    def __init__(self, settings: SingularConfig):
        super().__init__()
        self.settings = settings
        supported = settings.support > 0
        self._support = _support if supported else _no_support
        self._trust_supported = _trust_supported if supported else _as_tested
        self._gate = _no_gate if settings.gate is None else _gate

    def supported(self, obs: Observation) -> Optional[torch.Tensor]:
        """The pixels every test of this forward trusts (they depend on the observation only); None = no rule."""
        return self._support(obs, self.settings)

    def forward(self, obs: Observation, x: torch.Tensor, matches: BlockMatches,
                held: Optional[tuple[torch.Tensor, torch.Tensor, Optional[torch.Tensor]]] = None
                ) -> tuple[torch.Tensor, torch.Tensor, Optional[torch.Tensor]]:
        """``(Q, confidence, clean)`` of ``x`` against ``obs.y``: Q and the soft confidence P(x_i) (0 at missing
        pixels) (B,1,h,w), and the gate's verdict (B,1,1,1) bool, None without a gate. ``obs.supported`` is what
        :meth:`supported` returned; Q is 0 at ``obs.untrusted``, whatever the test and the gate say. With
        ``obs.update_region`` the test runs for that region, every other pixel keeps ``held`` (its incoming Q and
        confidence), and the gate keeps its incoming verdict (``held[2]``, when there is one): what the layer computes
        at a pixel then depends on the pixels near it only, so it may run on a crop around the region."""
        c = self.settings
        region = obs.update_region if held is not None else None
        with stage(obs.log.timings, "singular", x.device), torch.no_grad():
            q, conf = detect_singular(obs.y, x.detach(), obs.observed, matches, sigma_floor=c.sigma_floor,
                                      tau=c.tau, rounds=c.rounds, return_confidence=True, region=region,
                                      reach=obs.block_matcher.settings.window_and_k()[obs.task][0] // 2)
            if region is not None:
                q = torch.where(region, q, held[0].to(q))
                conf = torch.where(region, conf, held[1].to(conf))
            q, conf = self._trust_supported(obs, q, conf, c)
            if region is not None and held[2] is not None and c.gate is not None:
                clean = held[2]
                q = torch.where(clean, obs.observed.to(q.dtype), q)  # the gate's action, with its incoming verdict
            else:
                q, clean = self._gate(obs, q, conf, c)
            q = _distrust(obs, q)
        return q.to(x.dtype), conf.to(x.dtype), clean

    def extra_repr(self) -> str:
        s = self.settings
        return f"tau={s.tau:.3g}, rounds={s.rounds}, support={s.support}, gate={s.gate}"


# ---- the x-update -----------------------------------------------------------------------------------
def _neumann(q: torch.Tensor, diag: Optional[torch.Tensor], mu: torch.Tensor, K) -> NeumannPreconditioner:
    """The preconditioner of the system with KᵀQK replaced by mean(Q)/s² (KᵀK maps a constant image to 1/s² of it)
    and the diagonal by its mean."""
    a = q.flatten(1).mean(1) / (K.scale ** 2)  # (B,)
    if diag is not None:
        a = a + diag.flatten(1).mean(1)
    return NeumannPreconditioner(a.detach(), mu.detach())


def _region_diagonal(q: torch.Tensor, diag: Optional[torch.Tensor], mu: torch.Tensor, K,
                     m: torch.Tensor) -> Callable[[torch.Tensor], torch.Tensor]:
    """A region's preconditioner (``m`` its 0/1 mask): the operator's diagonal, KᵀQK by what it makes of a constant
    image (Q itself when K = I) and DᵀD by each pixel's count of in-image 4-neighbours. The Neumann preconditioner
    solves over the whole frame, 13 ms a layer at 640×480 for a region of a tenth of it. A sample whose region is
    the whole frame keeps the Neumann preconditioner: its layer is the model's own."""
    d = K.adjoint(q * K(torch.ones_like(m))) + mu.detach() * laplacian_diagonal(m)
    if diag is not None:
        d = d + diag
    inverse = (m / d.clamp_min(torch.finfo(d.dtype).tiny)).detach()
    whole = (m.flatten(1).amin(1) > 0).view(-1, 1, 1, 1)  # (B,1,1,1)
    if host_path(m.device) and not bool(whole.any()):
        return lambda r: inverse * r
    neumann = _neumann(q, diag, mu, K)
    return lambda r: torch.where(whole, neumann(r), inverse * r)


def _no_preconditioner(*args) -> None:
    return None


class LinearSolver(nn.Module):
    r"""The x-update of layer ``index``: :math:`(K^\top QK + \mathrm{diag} + \mu D^\top D)\,x = \mathrm{rhs}` by
    preconditioned CG (:func:`~torch_depth_sr.solvers.implicit.cg_solve`) warm-started at the current estimate,
    settings :class:`~torch_depth_sr.config.SolverConfig`. ``diag`` (B,1,H,W) holds the diagonal terms (the guided
    prior's β(1−Q), the value prior's weights; None when no term has one). With a fixed iteration count for the layer
    (``settings.iterations(index)``) CG runs that many iterations (a sample that reaches ``settings.tol`` earlier
    stops changing) and never makes the host wait for the device; without one it iterates until every sample
    reaches ``settings.tol`` (at most ``settings.max_iter``). With ``obs.update_region`` it solves for the region's
    pixels alone, every other pixel fixed at ``x0``, preconditioned by the operator's diagonal (a sample whose region
    is the whole frame as without one). Appends the ``(B,)`` iteration counts to ``obs.log.cg_iterations`` and times
    itself as ``"cg"``."""

    def __init__(self, settings: SolverConfig, index: int):
        super().__init__()
        self.settings, self.index = settings, index
        fixed = settings.iterations(index)
        self.max_iter = settings.max_iter if fixed is None else fixed
        self.early_exit = fixed is None
        self._preconditioner = _neumann if settings.precondition else _no_preconditioner
        self._region_preconditioner = _region_diagonal if settings.precondition else _no_preconditioner

    def forward(self, obs: Observation, q: torch.Tensor, mu: torch.Tensor, rhs: torch.Tensor, x0: torch.Tensor,
                diag: Optional[torch.Tensor] = None) -> torch.Tensor:
        c, K = self.settings, obs.K
        q = q.detach()

        def apply_a(v: torch.Tensor) -> torch.Tensor:
            av = K.adjoint(q * K(v)) + mu * laplacian(v)
            return av if diag is None else av + diag * v

        region = obs.update_region
        with stage(obs.log.timings, "cg", x0.device):
            if region is None:
                op, b, start, pre = apply_a, rhs, x0.detach(), self._preconditioner(q, diag, mu, K)
            else:  # A_RR x_R = b_R − A_RF x_F: the unknowns in the region, the other pixels fixed at x0
                m = region.to(x0.dtype)
                fixed = (1 - m) * x0.detach()
                op, b, start = (lambda v: m * apply_a(m * v)), m * (rhs - apply_a(fixed)), m * x0.detach()
                pre = self._region_preconditioner(q, diag, mu, K, m)
            res = cg_solve(op, b, x0=start, precond=pre, tol=c.tol, max_iter=self.max_iter,
                           implicit=c.implicit_backward, params=(mu,) if mu.requires_grad else (),
                           early_exit=self.early_exit, backward_max_iter=c.max_iter)
            x = res.x if region is None else m * res.x + fixed
        obs.log.cg_iterations.append(res.iterations)
        return x

    def extra_repr(self) -> str:
        s = self.settings
        return (f"iterations={self.max_iter if not self.early_exit else None}, tol={s.tol:.3g}, "
                f"max_iter={s.max_iter}, precondition={s.precondition}")
