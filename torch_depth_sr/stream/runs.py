"""The static runs of a stream frame: what the change test's verdicts make of each pixel's measurement and state.

Two per-pixel updates, one on each side of the model (:class:`~torch_depth_sr.stream.frame.StreamFrame`):

* :func:`join_runs` (before the model) — the measurement of a static pixel joins the mean of its run, and the model
  sees the mean (every stage that reads y, the data term and the do-no-harm band included). A measurement that
  matches no previous value near it where the past was measured confidently is an outlier in time: taken as missing
  (held at the past) and remembered. One that left the run's mean by more than ``outlier_test`` noise levels starts a
  new run when the previous frame's held-out or dropped value was the same (confirmed: a pole, an edge that moved, a
  surface that stepped); a first departure from a confident run is held out (the pixel keeps its run's mean) and
  remembered (at a depth edge a mixed or flying pixel takes the other side's depth in single frames: a new mean each
  time flipped the edge from frame to frame). The temporal prior's weight is ``weight × age`` on static pixels that
  did not restart; a hole the past did not measure confidently gets at most ``unmeasured_frames`` of age (its fill
  is the frame's own, damped over a few frames only).
* :func:`grow_runs` (after the model) — each run's age, evidence, confidence and mean for the next frame.

Each is a chain of about thirty whole-frame torch operations, each with a temporary (6–8 ms of a 0.15 s ``fast``
step at 640×480); on the CPU without gradient a numba kernel (:mod:`~torch_depth_sr.stream.runs_kernel`) makes the
same values in one pass, with the same float32/float64 operations in the same order (bit for bit, tested).
"""
from __future__ import annotations

import math
from typing import NamedTuple, Union

import torch

from ..config import StreamConfig
from ..native import host_kernel

__all__ = ["JoinedRuns", "GrownRuns", "grow_runs", "join_runs"]


class JoinedRuns(NamedTuple):
    """:func:`join_runs`' maps, (B,1,H,W); ``departed`` in depth units, the rest in the frame's normalised units."""

    y: torch.Tensor  # the model's measurement: the run's mean where averaged or held out, 0 on an outlier in time
    observed: torch.Tensor  # 0 on an outlier in time
    outlier: torch.Tensor  # bool: an outlier in time (dropped)
    held_out: torch.Tensor  # bool: a first departure from a confident run (the pixel keeps the mean)
    averaged: torch.Tensor  # bool: y is the mean of the static run's measurements
    restarted: torch.Tensor  # bool: a confirmed departure: a new run, no temporal pull this frame
    weight: torch.Tensor  # the temporal prior's weight
    departed: torch.Tensor  # the held-out or dropped measurement, for the next frame (0: none)
    fresh: torch.Tensor  # bool: changed, or a run younger than settled_frames (the later layers run here)


def join_runs(y: torch.Tensor, observed: torch.Tensor, static: torch.Tensor, candidate: torch.Tensor,
              noise: torch.Tensor, evidence: torch.Tensor, mean: torch.Tensor, departed: torch.Tensor,
              age: torch.Tensor, offset: torch.Tensor, scale: torch.Tensor, s: StreamConfig) -> JoinedRuns:
    """This frame's measurement ``y`` (normalised by ``offset``, ``scale`` (B,)) and ``observed`` joined to the runs
    of the previous frame's ``evidence``, ``mean``, ``departed`` (depth units) and ``age``: ``static`` and the
    change test's ``candidate`` outliers (bool), ``noise`` the local noise level (normalised). Module docstring."""
    kernel = host_kernel("stream.runs_kernel", "join_runs_cpu", y, observed, noise, evidence, mean, departed, age)
    if kernel is not None and all(t.shape == y.shape for t in (observed, noise, evidence, mean, departed, age)):
        return JoinedRuns(*kernel(y, observed, static, candidate, noise, evidence, mean, departed, age, offset,
                                  scale, s))
    o4, s4 = offset.view(-1, 1, 1, 1), scale.view(-1, 1, 1, 1)
    had = (mean > 0) & (evidence > 0)
    mean = (mean - o4) / s4
    limit = (s.outlier_test or math.inf) * noise
    pending = (departed - o4) / s4
    confirmed = (departed > 0) & (observed > 0) & ((y - pending).abs() <= limit)
    outlier = candidate & (evidence >= s.fill_evidence) & ~confirmed
    dropped = torch.where(outlier, y * s4 + o4, torch.zeros_like(y))
    observed = torch.where(outlier, torch.zeros_like(observed), observed)
    y = torch.where(outlier, torch.zeros_like(y), y)
    leaving = static & (observed > 0) & had & ((y - mean).abs() > limit)
    held_out = leaving & ~confirmed & (evidence >= s.fill_evidence)
    departed = torch.where(held_out, y * s4 + o4, dropped)
    y = torch.where(held_out, mean, y)
    measured = observed > 0
    restarted = leaving & ~held_out
    averaged = static & measured & had & ~restarted
    y = torch.where(averaged, (y + evidence * mean) / (evidence + 1), y)
    unmeasured = ~measured & (evidence < s.fill_evidence)
    aged = torch.where(unmeasured, age.clamp(max=s.unmeasured_frames), age)
    weight = torch.where(static & ~restarted, s.weight * aged, torch.zeros_like(evidence))
    fresh = ~static | (age + 1 < s.settled_age())
    return JoinedRuns(y, observed, outlier, held_out, averaged, restarted, weight, departed, fresh)


class GrownRuns(NamedTuple):
    """:func:`grow_runs`' maps (B,1,H,W) for the next frame, and two shares of this frame's pixels."""

    age: torch.Tensor  # frames of the static run, at most max_frames
    evidence: torch.Tensor  # trusted measurements of the run, decaying over holes
    confidence: torch.Tensor  # the model's where measured, the past's decayed on a static hole, else 0
    mean: torch.Tensor  # the run's mean measurement (depth units; 0: none)
    # the share of pixels that are holes filled from a confident past, and of static pixels: floats from the CPU
    # kernel, 0-d tensors from the torch path (read on the host only when asked: a GPU does not wait for them)
    filled_from_past: Union[float, torch.Tensor]
    static: Union[float, torch.Tensor]


def grow_runs(y: torch.Tensor, observed: torch.Tensor, trusted: torch.Tensor, confidence: torch.Tensor,
              static: torch.Tensor, restarted: torch.Tensor, evidence: torch.Tensor, age: torch.Tensor,
              past_confidence: torch.Tensor, past_mean: torch.Tensor, offset: torch.Tensor, scale: torch.Tensor,
              s: StreamConfig) -> GrownRuns:
    """The runs after this frame: ``y`` the model's measurement (normalised by ``offset``, ``scale`` (B,)),
    ``observed``, the model's ``trusted`` pixels (bool) and ``confidence`` where measured, :func:`join_runs`'
    ``static`` and ``restarted`` (bool), and the previous frame's ``evidence``, ``age``, ``past_confidence`` and
    ``past_mean`` (depth units), the float maps of one dtype. Module docstring."""
    maps = (y, observed, confidence, evidence, age, past_confidence, past_mean)
    kernel = host_kernel("stream.runs_kernel", "grow_runs_cpu", *maps)
    if kernel is not None and all(t.shape == y.shape and t.dtype == y.dtype for t in maps):
        return GrownRuns(*kernel(y, observed, trusted, confidence, static, restarted, evidence, age, past_confidence,
                                 past_mean, offset, scale, s))
    measured = observed > 0
    one = trusted.to(y.dtype)
    aged = torch.where(static, torch.clamp(age + 1, max=s.max_frames), torch.ones_like(one))
    grown = torch.clamp(evidence + 1, max=s.max_frames)
    held = torch.where(measured, evidence, evidence * s.hole_decay)
    new_evidence = torch.where(static & ~restarted, torch.where(trusted, grown, held), one)
    zero = torch.zeros_like(y)
    confidence = torch.where(measured, confidence, torch.where(static, past_confidence * s.hole_decay, zero))
    ymean = torch.where(measured, y * scale.view(-1, 1, 1, 1) + offset.view(-1, 1, 1, 1), zero)
    mean = torch.where(measured, ymean, torch.where(static, past_mean, zero))
    filled = ~measured & static & (evidence >= s.fill_evidence)
    return GrownRuns(aged, new_evidence, confidence, mean, filled.float().mean(), static.float().mean())
