"""Singular-pixel detection (paper eq. 2-5): is ``y_i`` plausible given its similar blocks?

For pixel ``i`` with matched centres ``j_1 … j_k`` and weights ``ω_{i m}``, restricted to the
currently credible centres (``Q_j = 1``) and renormalised,

.. math::

    \\tilde\\omega_{i m} = \\frac{\\omega_{i m} Q_{j_m}}{\\sum_{m'} \\omega_{i m'} Q_{j_{m'}}}, \\qquad
    \\mu_i = \\sum_m \\tilde\\omega_{i m} x_{j_m}, \\qquad
    \\sigma_i^2 = \\sum_m \\tilde\\omega_{i m} (x_{j_m} - \\mu_i)^2,

    \\sigma_i \\leftarrow \\max(\\sigma_i, \\sigma_{floor}), \\qquad
    P_i = \\exp\\Big(-\\frac{(y_i - \\mu_i)^2}{2\\sigma_i^2}\\Big), \\qquad
    Q_i = [P_i \\ge \\tau] \\cdot \\text{observed}_i .

The unnormalised Gaussian kernel is the reference reading (the paper's normalised density would mark
every pixel singular for ``σ > 0.4``); the floor ``σ_floor`` (the noise level) keeps flat regions from
marking every noisy pixel singular. The test is repeated: pixels found singular leave the statistics,
``μ, σ`` are recomputed, and so on for ``rounds`` rounds or until ``Q`` stops changing. Where no
matched centre is credible, the statistics use all ``k`` centres with their original weights.
"""
from __future__ import annotations

import math
from typing import Optional, Tuple, Union

import torch

from ._checks import check_4d, check_per_sample, check_same_hw
from .block_matching import BlockMatches, gather_neighbors
from .errors import DepthSRError
from .native import cpu_kernel, host_kernel, host_path
from .window_max import dilate

__all__ = ["detect_singular", "neighbour_support", "line_support"]


def _as_batch(value, name: str, b: int, like: torch.Tensor) -> torch.Tensor:
    """``(B,1,1,1)`` of a float or a ``(B,)``/one-element tensor, refused unless finite and > 0.

    A float is checked on the host; a tensor's check reads it (one host synchronisation on a GPU).
    """
    if isinstance(value, torch.Tensor):
        check_per_sample(value, name, b)
        v = value.detach().to(like).reshape(-1).expand(b) if value.numel() == 1 else value.detach().to(like)
        if bool((~torch.isfinite(v) | (v <= 0)).any()):
            raise DepthSRError(f"{name} must be finite and > 0; got {v.tolist()}.")
    else:
        if not (math.isfinite(float(value)) and float(value) > 0):
            raise DepthSRError(f"{name} must be finite and > 0; got {float(value)!r}.")
        v = torch.full((b,), float(value), dtype=like.dtype, device=like.device)
    return v.view(b, 1, 1, 1)


def neighbour_support(y: torch.Tensor, observed: torch.Tensor, tol: Union[float, torch.Tensor]) -> torch.Tensor:
    """Number of measured 8-neighbours whose value lies within ``tol`` of each pixel's, ``(B,1,H,W)``.

    A pixel on a surface, even right at a depth edge, has neighbours on its own side that agree with it;
    flying pixels and impulses float alone. ``tol`` is a float or a ``(B,)`` tensor in ``y``'s units.

    Examples:
        >>> y = torch.full((1, 1, 5, 5), 10.0); y[0, 0, 2, 2] = 50.0  # an impulse on a plane
        >>> s = neighbour_support(y, torch.ones_like(y), 1.0)
        >>> int(s[0, 0, 2, 2]), int(s[0, 0, 0, 0]), int(s[0, 0, 1, 1])
        (0, 3, 7)
    """
    return _Agreement(y, observed, tol).count


_OFFSETS = tuple((dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0))


def _measured(y: torch.Tensor, observed: torch.Tensor, tol) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Checked inputs of the neighbour tests: the measured mask, ``y`` with 0 elsewhere, ``tol`` as (B,1,1,1)."""
    check_4d(y, "y", channels=1)
    check_same_hw(y, observed, "y", "observed")
    b = y.shape[0]
    tol_t = torch.as_tensor(tol, dtype=y.dtype, device=y.device).reshape(-1)
    tol_t = tol_t.expand(b).view(b, 1, 1, 1) if tol_t.numel() == 1 else tol_t.view(b, 1, 1, 1)
    obs = (observed > 0) & torch.isfinite(y)
    return obs, torch.where(obs, y, torch.zeros_like(y)), tol_t


class _Shifts:
    """The 8-neighbours of every pixel of ``t`` as views of one padded copy: ``shifts(dy, dx)`` holds at pixel
    ``i`` the value at ``i + (dy, dx)``, ``fill`` outside the image (one pad per plane, not one per neighbour)."""

    def __init__(self, t: torch.Tensor, fill) -> None:
        self.h, self.w = t.shape[-2:]
        self.padded = torch.nn.functional.pad(t, (1, 1, 1, 1), value=fill)

    def __call__(self, dy: int, dx: int) -> torch.Tensor:
        return self.padded[..., 1 + dy:1 + dy + self.h, 1 + dx:1 + dx + self.w]


class _Agreement:
    """Which measured 8-neighbours agree with each measured pixel (within ``tol``): what :func:`neighbour_support`
    counts and :func:`line_support` reads, computed once when a rule asks for both."""

    def __init__(self, y: torch.Tensor, observed: torch.Tensor, tol) -> None:
        self.obs, self.yv, self.tol = _measured(y, observed, tol)
        self.values, self.measured = _Shifts(self.yv, 0.0), _Shifts(self.obs, False)
        self.agree = {}
        count = torch.zeros_like(self.yv)
        for dy, dx in _OFFSETS:
            a = self.measured(dy, dx) & ((self.values(dy, dx) - self.yv).abs() <= self.tol) & self.obs
            self.agree[dy, dx] = a
            count = count + a.to(self.yv.dtype)
        self.count = count  # 0 where not measured


def line_support(y: torch.Tensor, observed: torch.Tensor, tol: Union[float, torch.Tensor]) -> torch.Tensor:
    """Measured pixels on a thin structure, ``(B,1,H,W)`` bool: part of a chain of three or more agreeing pixels
    whose value does not lie between the values of its disagreeing neighbours.

    :func:`neighbour_support` asks for three agreeing 8-neighbours; a surface one pixel wide (a gap between
    two objects that shows the background, a wire) has two, its end one, and fails that test although it is
    measured as consistently as any surface. A flying pixel lies *between* the two sides of its edge and an
    impulse floats alone; neither is a chain whose value lies beyond its surroundings. Here a pixel is on a
    line when it agrees (within ``tol``) with a neighbour and one of the two has a second agreeing neighbour,
    its value lies two tolerances or more beyond the minimum or maximum of its measured disagreeing
    neighbours, and on two opposite sides it has a disagreeing neighbour (or the image's end, not on both).

    Examples:
        >>> y = torch.full((1, 1, 7, 7), 50.0); y[0, 0, :, 3] = 10.0  # a one-pixel gap showing the background
        >>> y[0, 0, 1, 5] = 30.0  # a lone pixel between the sides: not a line
        >>> s = line_support(y, torch.ones_like(y), 1.0)
        >>> bool(s[0, 0, 0, 3]), bool(s[0, 0, 3, 3]), bool(s[0, 0, 1, 5])
        (True, True, False)
    """
    return _lines(_Agreement(y, observed, tol))


def _lines(g: _Agreement) -> torch.Tensor:
    """:func:`line_support` from the agreement of the neighbours."""
    obs, yv, tol_t, count = g.obs, g.yv, g.tol, g.count
    lo = torch.full_like(yv, math.inf)
    hi = torch.full_like(yv, -math.inf)
    border = _Shifts(torch.zeros_like(obs), True)
    apart = {}
    for dy, dx in _OFFSETS:
        yn, on = g.values(dy, dx), g.measured(dy, dx)
        other = on & ~g.agree[dy, dx]
        lo = torch.where(other, torch.minimum(lo, yn), lo)
        hi = torch.where(other, torch.maximum(hi, yn), hi)
        apart[dy, dx] = other | border(dy, dx)  # a disagreeing neighbour, or the image's end (a line may run along it)
    chain = count >= 2  # the middle of a chain
    middle = _Shifts(chain, False)
    for (dy, dx), a in g.agree.items():  # the end of a chain: an agreeing neighbour in its middle
        chain = chain | (a & middle(dy, dx))
    # clearly beyond (two tolerances: a flying pixel near one side of its edge is not); none (lo = inf) is beyond
    beyond = (yv <= lo - 2 * tol_t) | (yv >= hi + 2 * tol_t)
    # thin: other surfaces on two opposite sides (a flying pixel beside a hole has a surface on one side only)
    between = torch.zeros_like(obs)
    for dy, dx in _OFFSETS[:4]:
        between = between | (apart[dy, dx] & apart[-dy, -dx] & (g.measured(dy, dx) | g.measured(-dy, -dx)))
    thin = count <= 2  # more agreeing neighbours make a surface (neighbour_support's case), not a line
    return chain & thin & beyond & between & obs


def supported_or_line(y: torch.Tensor, observed: torch.Tensor, tol: Union[float, torch.Tensor],
                      support: int) -> torch.Tensor:
    """``(neighbour_support(y, observed, tol) >= support) | line_support(y, observed, tol)`` from one look at the
    neighbours."""
    kernel = host_kernel("singular_kernel", "support_cpu", y.detach())
    if kernel is not None:  # the same tests, one pass over the pixels instead of ~100 over the image
        obs, yv, tol_t = _measured(y.detach(), observed, tol)
        return kernel(yv, obs, tol_t.reshape(-1), support)
    g = _Agreement(y, observed, tol)
    return (g.count >= support) | _lines(g)


def _numba_kernel():
    """:func:`~torch_depth_sr.singular_kernel.singular_rounds_cpu`, or None (see :mod:`torch_depth_sr.native`)."""
    return cpu_kernel("singular_kernel", "singular_rounds_cpu")


def _rounds_needed(region: torch.Tensor, rounds: int, reach: int) -> torch.Tensor:
    """(B,1,H,W) uint8: how many rounds each pixel takes part in for ``region``'s result. Round ``r`` of a pixel reads
    round ``r − 1`` at its matched centres, within ``reach`` px: ``rounds`` in the region, one fewer per ``reach`` px
    farther from it."""
    need = region.to(torch.uint8)
    grown = region
    for _ in range(rounds - 1):
        grown = dilate(grown, reach)
        need = need + grown.to(torch.uint8)
    return need


def _singular_torch(y0, obs, xv, matches: BlockMatches, floor, tau: float, rounds: int, early_exit=None):
    """The test in tensor operations (any device; the reference of the numba kernel).

    Runs ``rounds`` rounds. With ``early_exit`` (default: on the CPU) it stops once ``Q`` stops changing (a
    later round would give the same ``Q`` and ``P``); on other devices that test would make the host wait for
    the device every round, so every round runs.
    """
    if early_exit is None:
        early_exit = host_path(y0.device)
    dt = y0.dtype
    xj = gather_neighbors(xv, matches.index)[:, 0]  # (B, k, H, W)
    w0 = matches.weight.detach().to(dt)  # (B, k, H, W)
    q = obs.clone()
    p = torch.zeros_like(y0)
    for _ in range(rounds):
        qj = gather_neighbors(q.to(dt), matches.index)[:, 0]  # (B, k, H, W)
        w = w0 * qj
        s = w.sum(dim=1, keepdim=True)  # (B, 1, H, W)
        w = torch.where(s > 0, w / s.clamp_min(torch.finfo(dt).tiny), w0)
        mu = (w * xj).sum(dim=1, keepdim=True)  # (B, 1, H, W)
        var = (w * (xj - mu) ** 2).sum(dim=1, keepdim=True)
        sigma = torch.maximum(var.clamp_min(0).sqrt(), floor)
        p = torch.exp(-((y0 - mu) ** 2) / (2 * sigma**2)) * obs
        q_new = (p >= tau) & obs
        stop = early_exit and not bool((q_new != q).any())
        q = q_new
        if stop:
            break
    return q.to(dt), p


def detect_singular(
    y: torch.Tensor,
    x: torch.Tensor,
    observed: torch.Tensor,
    matches: BlockMatches,
    sigma_floor: Union[float, torch.Tensor],
    tau: float = 0.5,
    rounds: int = 3,
    *,
    return_confidence: bool = False,
    region: Optional[torch.Tensor] = None,
    reach: Optional[int] = None,
    backend: str = "auto",
) -> Union[torch.Tensor, Tuple[torch.Tensor, torch.Tensor]]:
    """Credibility mask ``Q`` (1 = credible, 0 = singular or missing) from the matched blocks.

    Args:
        y: ``(B, 1, H, W)`` observed depth (missing pixels may hold anything, NaN included).
        x: ``(B, 1, H, W)`` current estimate (defined everywhere); ``μ, σ`` come from it.
        observed: ``(B, 1, H, W)`` {0, 1} (or bool) mask of measured pixels; 0 → ``Q = 0`` always.
            NaN/inf values of ``y`` are treated as missing too.
        matches: :class:`~torch_depth_sr.block_matching.BlockMatches` of ``x`` (``(B, k, H, W)``).
        sigma_floor: ``σ_floor > 0``, float or ``(B,)`` tensor, in the units of ``y`` (the noise level).
        tau: threshold on ``P`` in ``(0, 1]`` (0.5, i.e. ``|y − μ| ≤ 1.177 σ``).
        rounds: number of test rounds (≥ 1). Once a round changes no pixel's ``Q`` the later ones would
            change nothing either; on the CPU the test then stops early.
        return_confidence: also return the soft confidence ``P`` (0 at missing pixels).
        region: None, or a ``(B, 1, H, W)`` bool map of the pixels whose ``Q`` and ``P`` are wanted; elsewhere they
            are left unspecified. The numba kernel then computes a round only where a later round or the result
            reads it: the region, and in round ``r`` the pixels within ``(rounds − 1 − r) · reach`` px of it.
        reach: how far from a pixel its matched centres lie, in px (the search window's radius): needed with
            ``region``.
        backend: ``"numba"`` (the CPU kernel of :mod:`~torch_depth_sr.singular_kernel`), ``"torch"`` (tensor
            operations, any device) or ``"auto"`` (numba for float CPU tensors when it is installed and
            ``TORCH_DEPTH_SR_NO_NUMBA`` is unset, else torch). Both give the same ``Q`` and ``P`` up to
            floating-point round-off.

    Returns:
        ``Q`` ``(B, 1, H, W)`` float {0, 1} in ``y``'s dtype, no gradient; with
        ``return_confidence=True`` the tuple ``(Q, P)``.

    Examples:
        >>> from torch_depth_sr.block_matching import block_match
        >>> g = torch.Generator().manual_seed(0)
        >>> x = torch.linspace(0, 10, 24).view(1, 1, 1, 24).expand(1, 1, 24, 24).contiguous()
        >>> y = x + 0.1 * torch.randn(x.shape, generator=g)
        >>> y[0, 0, 12, 12] += 5.0  # an impulse
        >>> m = block_match(x, None, None, block_size=5, search_window=11, k=8)
        >>> q = detect_singular(y, x, torch.ones_like(y), m, sigma_floor=0.3)
        >>> float(q[0, 0, 12, 12]), float(q.mean()) > 0.95
        (0.0, True)
    """
    check_4d(y, "y", channels=1)
    check_4d(x, "x", channels=1)
    check_4d(observed, "observed", channels=1)
    check_same_hw(y, x, "y", "x")
    check_same_hw(y, observed, "y", "observed")
    check_same_hw(y, matches.index, "y", "matches", "Run block matching on this image.")
    if not 0.0 < float(tau) <= 1.0:
        raise DepthSRError(f"tau must be in (0, 1]; got {tau!r}.")
    if isinstance(rounds, bool) or not isinstance(rounds, int) or rounds < 1:
        raise DepthSRError(f"rounds must be an int >= 1; got {rounds!r}.")
    if region is not None and (isinstance(reach, bool) or not isinstance(reach, int) or reach < 0):
        raise DepthSRError(f"with a region, reach must be an int >= 0 (the matches' search radius); got {reach!r}.")
    if backend not in ("auto", "numba", "torch"):
        raise DepthSRError(f"backend must be 'auto', 'numba' or 'torch'; got {backend!r}.")
    b = y.shape[0]
    with torch.no_grad():
        dt = y.dtype if y.is_floating_point() else torch.float32
        yv = y.detach().to(dt)
        xv = x.detach().to(dt)
        floor = _as_batch(sigma_floor, "sigma_floor", b, yv)
        obs = (observed.detach() > 0) & torch.isfinite(yv)  # (B,1,H,W) bool
        y0 = torch.where(obs, yv, torch.zeros_like(yv))
        kernel = None
        if backend != "torch" and host_path(y0.device) and dt in (torch.float32, torch.float64):
            kernel = _numba_kernel()
        if kernel is None and backend == "numba":
            raise DepthSRError("backend='numba' needs CPU float32/float64 tensors and numba (got tensors on "
                               f"{y0.device} in {dt}; numba {'missing or disabled' if _numba_kernel() is None else 'loaded'}).")
        if kernel is not None:
            need = None if region is None else _rounds_needed(region, rounds, reach)
            qf, p = kernel(y0, obs, xv, matches.index, matches.weight, floor, float(tau), rounds, need)
        else:
            qf, p = _singular_torch(y0, obs, xv, matches, floor, float(tau), rounds)
    return (qf, p) if return_confidence else qf

