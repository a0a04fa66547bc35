"""The shift test of a stream's change test: a window whose measurements the previous estimate matches much better
after a one-pixel shift than where it was, i.e. a depth edge that moved by a pixel.

The depth test of :func:`~torch_depth_sr.stream.change.change_test` compares each measurement with the nearest
previous value within one pixel, so that an edge the previous estimate placed a pixel off is no change. That
tolerance also hides a mover that advances by about a pixel a frame. The new values at its leading edge match its own
previous values a pixel behind, and the background it uncovers matches the background's previous values a pixel
ahead. With a colour near the background's, nothing else sees such a mover. Its edge pixels then left their runs a
frame late, every frame: held out as first departures, or dropped as outliers in time. The estimate lagged the mover,
and the lag spread through the runs' means and the temporal prior
(``docs/measurements/issue28-stream/history.md``, item 8).

The window as a whole tells the two apart. A moved edge shifts the window's whole pattern, so one of the eight
one-pixel shifts of the previous estimate matches the window much better than no shift does. A mixed or flying pixel
at an edge that stayed leaves the unshifted match good everywhere else in its window.

:func:`shifted_windows` marks a measured pixel whose ``WINDOW × WINDOW`` window departs from the previous estimate
and for which a one-pixel shift of that estimate brings the window's error below ``ratio`` times the unshifted
error. Each pixel's error is ``|y − previous| / noise``, clipped at ``CLIP`` so that one flying pixel weighs no more
than a departure. The window *departs* when one of its pixels is ``CLIP`` or more noise units off (a mean error above
one unit instead, or at least 2, 3 or 5 such pixels, found fewer of the movers:
``docs/measurements/issue28-stream/history.md``, item 8). The previous estimate is replicated at the border. The
shifted errors are summed only in the windows that depart, on the CPU by a numba kernel
(:func:`~torch_depth_sr.stream.shift_kernel.shifted_windows_cpu`). Its float64 sums are taken in the
torch path's order, so the results are the same bit for bit (tested).
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

from ..native import host_kernel, host_path
from ..window_max import dilate

__all__ = ["CLIP", "WINDOW", "shifted_windows"]

WINDOW = 5  # the window's side (px)
CLIP = 4.0  # the most one pixel's error counts, in noise units (the outlier test's 4 levels)
_SHIFTS = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx]


def shifted_windows(y: torch.Tensor, observed: torch.Tensor, previous: torch.Tensor, noise: torch.Tensor,
                    ratio: float) -> torch.Tensor:
    """(B,1,H,W) bool: measured pixels whose window departs from ``previous`` and matches one of its one-pixel shifts
    with less than ``ratio`` times the unshifted error (module docstring). ``y``, ``observed``, ``previous`` and
    ``noise`` (B,1,H,W) of one float dtype, ``noise > 0``, all in the units of one frame."""
    with torch.no_grad():
        measured = observed > 0
        far = measured & ((y - previous).abs() / noise >= CLIP)
        departs = measured & dilate(far, WINDOW // 2)  # a window with a pixel CLIP or more units off
        if host_path(y.device) and not bool(departs.any()):  # off the CPU no host read: the test gives False anyway
            return departs
        kernel = host_kernel("stream.shift_kernel", "shifted_windows_cpu", y, observed, previous, noise)
        if kernel is not None and all(t.shape == y.shape for t in (observed, previous, noise)) and y.shape[1] == 1:
            return kernel(y, observed, previous, noise, departs, ratio, WINDOW, CLIP)
        still = _window_sums(_errors(y, measured, previous, noise), WINDOW)
        padded = F.pad(previous, (1, 1, 1, 1), mode="replicate")
        h, w = y.shape[-2:]
        best = torch.full_like(still, float("inf"))
        for dy, dx in _SHIFTS:
            shifted = padded[..., 1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
            best = torch.minimum(best, _window_sums(_errors(y, measured, shifted, noise), WINDOW))
        return departs & (best < ratio * still)


def _errors(y: torch.Tensor, measured: torch.Tensor, previous: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
    """float64 ``min(|y − previous| / noise, CLIP)`` (the division in the frames' dtype) at measured pixels, else 0."""
    error = ((y - previous).abs() / noise).clamp(max=CLIP).double()
    return torch.where(measured, error, torch.zeros_like(error))


def _window_sums(v: torch.Tensor, window: int) -> torch.Tensor:
    """The sums of ``v`` (float64) over the ``window × window`` window (zero outside the image), added one offset
    after another, rows then columns: the kernel's order."""
    p = window // 2
    h, w = v.shape[-2:]
    padded = F.pad(v, (p, p, p, p))
    out = torch.zeros_like(v)
    for dy in range(window):
        for dx in range(window):
            out = out + padded[..., dy:dy + h, dx:dx + w]
    return out
