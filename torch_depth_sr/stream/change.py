"""The per-pixel change test of a stream: which pixels show the scene of the previous frame.

Each measured pixel is compared with the previous restored frame in units of its noise (:func:`distances`): ``d0``
with the previous value at the pixel, ``d1`` with the nearest of the previous values in its 3×3 neighbourhood (an
edge that the previous estimate placed one pixel off, or that moved by one pixel, is no change of the surface).

A pixel is *changed* (:func:`change_test`) when its colour or its depth changed around it:

* colour: the mean over the ``window × window`` window of the absolute colour change (averaged over the channels,
  after each channel's median change over the frame is removed: an exposure or white-balance step moves the whole
  frame, not the scene) exceeds ``color_test`` (colour in [0, 1]);
* depth: more than half of the measured pixels of the window have ``d1 > depth_test``. The noise unit is the local
  spread of the measurements about the restored depth in the previous frame (:func:`local_spread`, a window mean
  of ``|y − x|``: a sensor's noise grows with the distance, so one noise level for the frame would call every far
  surface changed), at least a quarter of the frame's noise level and the quantisation step. A majority vote is a
  median test: flying pixels and impulses, a minority of any window even at depth edges, flag nothing, while a
  surface that moved flags its whole window. Three pseudo-votes of "unchanged" join every window, so that a window
  of a few measured pixels among holes needs all of them;
* shift (``shift_test``): the window matches a one-pixel shift of the previous estimate much better than the
  estimate where it was (:mod:`~torch_depth_sr.stream.shift`): an edge that moved by a pixel, which the depth test's
  nearest value within one pixel does not see. Its unit is the run's bounded one (``join_cap``), at least 2 σ̂;
* drift (``drift_test``, :func:`drifting`): the measurements of the 5×5 window lie on one side of their runs' means,
  and the window's colour changed by at least ``DRIFT_COLOUR`` of ``color_test``. A slanted surface that slides by a
  pixel or two a frame (a moving object's face) moves the depth at a pixel by less than the depth test's unit each
  frame, within its one-pixel tolerance, and the run's mean would lag it; each measurement is within the noise, but
  together they all depart the same way. A real sensor's depth also drifts so on a still scene (a RealSense's, by
  several noise units over whole windows), but there the colour stays; a sliding surface carries its texture along.
  Without colour there is no drift test.

The changed pixels are then dilated by ``dilate`` pixels (a moving edge's neighbours). In a static window a single
measured pixel can still disagree with the past: if its value matches none of the previous values near it (``d1 >
outlier_test``) it is an *outlier in time* — a flying pixel, an impulse — that the stream drops where the past was
measured confidently, for one frame when the next measures the same value (a thin object that no window sees).
One that matches a neighbour's previous value (``d1`` small, ``d0`` large: an edge placed one
pixel off before, or a mixed pixel that took the other side's depth) is no outlier here; the stream holds it out
once, as a first departure from the pixel's run, and starts a new run when the next frame confirms it
(:class:`~torch_depth_sr.stream.restorer.StreamRestorer`).
"""
from __future__ import annotations

import functools
import math
from typing import NamedTuple, Optional

import torch
import torch.nn.functional as F

from ..config import StreamConfig
from ..native import host_kernel, host_path
from ..selection import lower_median
from ..window_max import dilate
from .shift import shifted_windows

__all__ = ["ChangeTest", "camera_moved", "change_test", "color_change", "colour_changes", "depth_votes", "distances",
           "drifting", "local_spread", "remembered_spread"]

_PRIOR = 6.0  # pseudo-votes of "unchanged" per window
# the drift test's window, and the bound (noise units) on what one measurement adds to its sum: a flying pixel or an
# impulse, far from its run's mean, weighs no more than a unit
DRIFT_WINDOW, DRIFT_CLIP = 5, 1.0
# the share of color_test that the window's colour change must reach for the drift test to count (half: a change
# the colour test alone does not call one)
DRIFT_COLOUR = 0.5


def _box_mean(v: torch.Tensor, window: int) -> torch.Tensor:
    """The mean of ``v`` (B,C,H,W) over the ``window × window`` window, zero padding (as ``avg_pool2d`` with
    ``count_include_pad``), from cumulative sums in float64 along rows then columns: a few passes over the image
    whatever the window, where ``avg_pool2d`` reads the whole window at every pixel, and exact to the rounding of
    the result. On the CPU without gradient by the numba kernel (:mod:`~torch_depth_sr.stream.box_kernel`, the same
    sums: the same means)."""
    kernel = host_kernel("stream.box_kernel", "box_mean_cpu", v) if window % 2 == 1 else None
    if kernel is not None:
        return kernel(v, window)
    p = window // 2
    d = F.pad(v.double(), (p + 1, p))
    c = d.cumsum(-1)
    d = F.pad(c[..., window:] - c[..., :-window], (0, 0, p + 1, p))
    c = d.cumsum(-2)
    return ((c[..., window:, :] - c[..., :-window, :]) / (window * window)).to(v.dtype)


def _window_mean(v: torch.Tensor, window: int,
                 weight: Optional[torch.Tensor] = None) -> tuple[torch.Tensor, torch.Tensor]:
    """The window means of ``v·weight`` and of ``weight`` (the weighted mean is their ratio), zero padding."""
    if weight is None:
        weight = torch.ones_like(v[:, :1])
    both = _box_mean(torch.cat([v * weight, weight], 1), window)  # one pass for the two (each channel on its own)
    return both[:, :-1], both[:, -1:]


def local_spread(y: torch.Tensor, observed: torch.Tensor, x: torch.Tensor, window: int) -> torch.Tensor:
    """(B,C,H,W): the window mean of ``|y − x|`` over the measured pixels (0 where the window has none): the local
    noise of the measurements about the restored depth ``x`` (B,C,H,W: C estimates, a spread about each)."""
    fits = (window % 2 == 1 and y.shape[1] == 1 and observed.shape == y.shape and x.shape[0] == y.shape[0]
            and x.shape[-2:] == y.shape[-2:] and observed.dtype == x.dtype == y.dtype)
    kernel = host_kernel("stream.box_kernel", "local_spread_cpu", y, observed, x) if fits else None
    if kernel is not None:  # the same sums, the planes made on the fly
        return kernel(y, observed, x, window)
    m = (observed > 0).to(y.dtype)
    num, den = _window_mean(torch.where(m > 0, (y - x).abs(), torch.zeros_like(x)), window, m)
    return torch.where(den > 0, num / den.clamp_min(1e-12), torch.zeros_like(num))


def remembered_spread(y: torch.Tensor, observed: torch.Tensor, x: torch.Tensor, past: torch.Tensor,
                      past_spread: torch.Tensor, static: torch.Tensor, window: int, memory: float) -> torch.Tensor:
    """(B,1,H,W): the noise unit a stream keeps for its next change test. :func:`local_spread` about the estimate
    ``x``, and where ``static`` at least the spread about the previous estimate ``past`` (how far the measurements
    moved since: a sensor whose depth steps between levels far away moves more from frame to frame than about any
    one estimate) and ``memory`` times the previous unit ``past_spread``. All (B,1,H,W) of one dtype, ``static``
    bool; on the CPU one numba pass without temporaries (:mod:`~torch_depth_sr.stream.box_kernel`, the same values)."""
    maps = (y, observed, x, past, past_spread)
    fits = window % 2 == 1 and all(t.shape == x.shape and t.dtype == x.dtype for t in maps) and x.shape[1] == 1
    kernel = host_kernel("stream.box_kernel", "remembered_spread_cpu", *maps) if fits else None
    if kernel is not None:
        return kernel(y, observed, x, past, past_spread, static, window, memory)
    both = local_spread(y, observed, torch.cat([x, past], 1), window)
    spread, innovation = both[:, :1], both[:, 1:]
    remembered = torch.maximum(innovation, memory * past_spread)
    return torch.where(static, torch.maximum(spread, remembered), spread)


def distances(y: torch.Tensor, observed: torch.Tensor, previous: torch.Tensor,
              noise: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(d0, d1)`` (B,1,H,W): ``|y − previous| / noise`` at the pixel and the smallest ``|y − previous_j| / noise``
    over the 3×3 neighbourhood ``j`` (the pixel included); 0 where ``y`` is not measured. ``noise`` (B,) or
    (B,1,H,W)."""
    noise = noise.view(-1, 1, 1, 1) if noise.ndim == 1 else noise
    h, w = y.shape[-2:]
    padded = F.pad(previous, (1, 1, 1, 1), mode="replicate")
    d0 = (y - previous).abs()
    d1 = d0
    for dy in range(3):
        for dx in range(3):
            if (dy, dx) != (1, 1):
                d1 = torch.minimum(d1, (y - padded[..., dy:dy + h, dx:dx + w]).abs())
    m = observed > 0
    zero = torch.zeros_like(d0)
    return torch.where(m, d0 / noise, zero), torch.where(m, d1 / noise, zero)


def _nearest_distance(y: torch.Tensor, observed: torch.Tensor, previous: torch.Tensor,
                      noise: torch.Tensor) -> torch.Tensor:
    """``distances(...)[1]``; on the CPU by the numba kernel (:mod:`~torch_depth_sr.stream.change_kernel`, the same
    values) where every input has the frame's shape and dtype (``noise`` may be one value per sample)."""
    n = noise.view(-1, 1, 1, 1) if noise.ndim == 1 else noise
    fits = (y.shape[1] == 1 and observed.shape == y.shape == previous.shape and n.shape[:2] == y.shape[:2]
            and n.shape[-2:] in ((1, 1), y.shape[-2:]) and all(t.dtype == y.dtype for t in (observed, previous, n)))
    kernel = host_kernel("stream.change_kernel", "nearest_distance_cpu", y, observed, previous, n) if fits else None
    if kernel is not None:
        return kernel(y, observed, previous, n)
    return distances(y, observed, previous, noise)[1]


def depth_votes(d1: torch.Tensor, observed: torch.Tensor, window: int, threshold: float) -> torch.Tensor:
    """(B,1,H,W): the share of the window's votes that say "changed" (measured pixels with ``d1 > threshold``)
    among the measured pixels and three pseudo-votes of "unchanged"."""
    n = window * window
    fits = window % 2 == 1 and observed.dtype == d1.dtype and observed.shape == d1.shape and d1.shape[1] == 1
    kernel = host_kernel("stream.change_kernel", "votes_cpu", d1, observed) if fits else None
    if kernel is not None:  # the window counts, exact, and the votes with the roundings below
        return kernel(d1, observed, threshold, window, _PRIOR)
    m = (observed > 0).to(d1.dtype)
    far = ((d1 > threshold) & (m > 0)).to(d1.dtype)
    num, den = _window_mean(far, window, m)
    return (num * n) / (den * n + _PRIOR)


def drifting(y: torch.Tensor, observed: torch.Tensor, run_mean: torch.Tensor, has_run: torch.Tensor,
             noise: torch.Tensor, test: float) -> torch.Tensor:
    """(B,1,H,W) bool: the window's measurements drift from their runs' means. Over the ``DRIFT_WINDOW²`` window, the
    ``n`` pixels measured now (``observed``) with a run (``has_run``, bool) add ``(y − run_mean) / noise`` each,
    clipped to ``±DRIFT_CLIP``; the window drifts where ``n ≥ 3`` and the sum exceeds ``test · √n``. On a static
    surface the terms are independent noise of mean 0, and their sum's spread is at most ``√n`` (each term's at most
    1): ``test`` is a z-score. A surface that moved by a unit or more since the runs began gives each term its full
    ``±1``, a sum of ``n`` (``√n = 5`` z-scores in a full window). On the CPU one numba pass without temporaries
    (:mod:`~torch_depth_sr.stream.box_kernel`, the same verdicts)."""
    maps = (y, observed, run_mean, noise)
    fits = all(t.shape == y.shape and t.dtype == y.dtype for t in maps) and has_run.shape == y.shape and y.shape[1] == 1
    kernel = host_kernel("stream.box_kernel", "drift_cpu", *maps) if fits else None
    if kernel is not None:
        return kernel(y, observed, run_mean, has_run, noise, test, DRIFT_WINDOW, DRIFT_CLIP)
    both = (observed > 0) & has_run
    d = ((y - run_mean) / noise).clamp(-DRIFT_CLIP, DRIFT_CLIP)
    d = torch.where(both, d, torch.zeros_like(d))
    sums = _box_mean(torch.cat([d, both.to(d.dtype)], 1), DRIFT_WINDOW) * (DRIFT_WINDOW * DRIFT_WINDOW)
    total, n = sums[:, :1], sums[:, 1:]
    return (n >= 2.5) & (total.abs() > test * n.clamp_min(0).sqrt())


@torch.no_grad()
def camera_moved(rgb: torch.Tensor, previous: torch.Tensor, reach: int = 2) -> torch.Tensor:
    """(B,) the ratio of the smallest mean colour change over the frame after a shift of the previous image by up to
    ``reach`` px (not 0) to the mean change without a shift: well below 1 when the camera moved (the whole image
    moved), about 1 or above when only some objects did, 1 when the image did not change at all. On the CPU the 25
    means come from one pass of a numba kernel (:mod:`~torch_depth_sr.stream.change_kernel`) with float64 sums."""
    a, b = rgb.mean(1, keepdim=True), previous.mean(1, keepdim=True)
    kernel = host_kernel("stream.change_kernel", "shift_changes_cpu", a, b) if min(a.shape[-2:]) > 2 * reach else None
    if kernel is not None:
        changes = kernel(a[:, 0], b[:, 0], reach)  # (B, (2·reach + 1)²) float64, the unshifted one in the middle
        middle = changes.shape[1] // 2
        still = changes[:, middle]
        best = torch.cat([changes[:, :middle], changes[:, middle + 1:]], 1).min(1).values
        ratio = torch.where(still > 1.0 / 255, best / still.clamp_min(1e-12), torch.ones_like(still))
        return ratio.to(rgb.dtype)
    a = a - a.flatten(1).mean(1).view(-1, 1, 1, 1)
    b = b - b.flatten(1).mean(1).view(-1, 1, 1, 1)
    core = a[..., reach:-reach, reach:-reach]
    h, w = core.shape[-2:]
    buf = torch.empty_like(core)  # one buffer for the 25 differences (in place: a third of the time)

    def change(dy: int, dx: int) -> torch.Tensor:
        shifted = b[..., reach + dy:reach + dy + h, reach + dx:reach + dx + w]
        return torch.sub(core, shifted, out=buf).abs_().flatten(1).mean(1)

    still = change(0, 0)
    best = torch.full_like(still, float("inf"))
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            if dy or dx:
                best = torch.minimum(best, change(dy, dx))
    # an image that did not change (the mean change below 1/255) did not move, however well a shift matches it
    return torch.where(still > 1.0 / 255, best / still.clamp_min(1e-12), torch.ones_like(still))


def color_change(rgb: torch.Tensor, previous: torch.Tensor, window: int) -> torch.Tensor:
    """(B,1,H,W): the window mean of the absolute colour change, each channel's median change removed."""
    return colour_changes(rgb, previous, window)[0]


def colour_changes(rgb: torch.Tensor, previous: torch.Tensor, window: int,
                   test: float = math.inf) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`color_change`, and where each pixel's own mean absolute colour change (no median removed) exceeds
    ``test`` (B,1,H,W) bool: one pass over the colour on the CPU (:mod:`~torch_depth_sr.stream.change_kernel`, the
    same values)."""
    diff = rgb - previous
    median = lower_median(diff.flatten(2))
    kernel = host_kernel("stream.change_kernel", "colour_change_cpu", diff, median)
    if kernel is not None:
        change, own = kernel(diff, median, test)
    else:
        change = (diff - median[..., None, None]).abs().mean(1, keepdim=True)
        own = diff.abs().mean(1, keepdim=True) > test
    return _box_mean(change, window) / _inside_share(change, window), own


def _inside_share(like: torch.Tensor, window: int) -> torch.Tensor:
    """(1,1,H,W): the share of each pixel's window that lies in the image, as ``_box_mean`` of ones gives it (the
    count of in-image pixels over ``window²``, one rounding to ``like``'s dtype): from the rows' and columns' counts,
    not a box filter of a plane of ones. The same for every frame of a stream: kept per size (a read-only plane)."""
    return _inside_share_of(*like.shape[-2:], window, like.dtype, like.device)


@functools.lru_cache(maxsize=8)
def _inside_share_of(h: int, w: int, window: int, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    p = window // 2

    def inside(n):  # per position along an axis: the window's positions in [0, n)
        i = torch.arange(n, device=device)
        return (torch.clamp(i + p + 1, max=n) - torch.clamp(i - p, min=0)).to(torch.float64)

    return (inside(h)[:, None] * inside(w)[None, :] / (window * window)).to(dtype).view(1, 1, h, w)


class ChangeTest(NamedTuple):
    """The outcome of :func:`change_test`, each (B,1,H,W) bool."""

    changed: torch.Tensor  # the window test, dilated: the pixel starts a new static run
    outlier: torch.Tensor  # in a static window, a measurement that matches no previous value near it
    seen: torch.Tensor  # the change as the colour alone sees it (dilated), or as changed without colour
    own: Optional[torch.Tensor] = None  # the pixel's own mean colour change exceeds color_test (None: no colour)


def change_test(y: torch.Tensor, observed: torch.Tensor, previous: torch.Tensor, noise: torch.Tensor,
                rgb: Optional[torch.Tensor], previous_rgb: Optional[torch.Tensor],
                settings: StreamConfig, shift_noise: Optional[torch.Tensor] = None,
                runs: Optional[tuple[torch.Tensor, torch.Tensor]] = None) -> ChangeTest:
    """The change test of one frame (module docstring); ``y``, ``previous`` and ``noise`` in the units of one
    frame. Without ``settings.outlier_test`` no pixel is an *outlier*. With ``settings.shift_test`` a window that a
    one-pixel shift of ``previous`` matches better is changed too (:func:`~torch_depth_sr.stream.shift.shifted_windows`,
    in units of ``shift_noise``, by default ``noise``). With ``settings.drift_test`` and ``runs`` (the previous
    frame's run means, in the units of ``y``, and where a run has one, bool) a window whose measurements drift from
    their runs' means and whose colour changed by ``DRIFT_COLOUR`` of ``color_test`` is changed too
    (:func:`drifting`)."""
    with torch.no_grad():
        d1 = _nearest_distance(y, observed, previous, noise)
        changed = depth_votes(d1, observed, settings.window, settings.depth_test) > 0.5
        if settings.shift_test is not None:
            unit = (noise if shift_noise is None else shift_noise).expand_as(y)
            changed = changed | shifted_windows(y, observed, previous, unit, settings.shift_test)
        seen = own = None
        if rgb is not None and previous_rgb is not None:
            previous_rgb = previous_rgb.to(rgb)
            colour, own = colour_changes(rgb, previous_rgb, settings.window, settings.color_test)
            if settings.drift_test is not None and runs is not None:
                gate = colour > DRIFT_COLOUR * settings.color_test
                # the window sums only where the colour lets the test count (on the host, none on a still scene)
                if not (host_path(y.device) and not gate.any()):
                    drift = drifting(y, observed, runs[0], runs[1], noise.expand_as(y), settings.drift_test)
                    changed = changed | (drift & gate)
            seen = dilate(colour > settings.color_test, settings.dilate)
            if settings.camera_test is not None and min(rgb.shape[-2:]) > 8:
                moved = (camera_moved(rgb, previous_rgb) < settings.camera_test).view(-1, 1, 1, 1)
                seen = seen | moved
        changed = dilate(changed, settings.dilate)
        changed = changed if seen is None else changed | seen
        seen = changed if seen is None else seen
        if settings.outlier_test is None:
            return ChangeTest(changed, torch.zeros_like(changed), seen, own)
        return ChangeTest(changed, ~changed & (d1 > settings.outlier_test), seen, own)
