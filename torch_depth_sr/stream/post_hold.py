"""The post-steps of a stream frame where the layers' value moved; elsewhere the previous output is held.

On sensor input a cold frame spends about as long in its post-steps as in its layers: flying pixels make the singular
gate switch the edge steps on, and the edge snap and the edge refit sort a colour window at every pixel near a depth
edge (:mod:`~torch_depth_sr.edge_snap`; 180–210 ms of a 480 ms frame at 640×480 on a 2-core CPU). In a stream, a
static pixel whose run has its full mean (``fresh`` False: the pixels the later layers leave alone,
:mod:`~torch_depth_sr.stream.later_layers`) and whose layers' value stayed within ``StreamConfig.hold`` noise units of
the value its previous output was computed from is *steady*: it keeps that output. The edge steps act on the other
pixels only, which the CPU kernels compute alone. The refiner runs on the whole frame (a few convolutions) and is
kept at those pixels only. The do-no-harm bounds (the steps with ``bounds_output``: the band,
:class:`~torch_depth_sr.post_steps.FidelityBandStep`) then bound the whole frame as in a cold one.

The test is on the layers' value, not the change test alone: a change the change test misses still moves the layers'
value towards the measurements, and the pixel gets the post-steps again once it has moved by ``hold`` units. Holding
the output without it let such a change stay for as long as the pixel was called static, and gave an RMSE above
frame by frame's on one evaluated sequence; holding only the post-steps' correction passed the layers'
frame-to-frame change through at edges, where the refit's median is steadier, and raised the flicker by half
(``docs/measurements/h100-2026-12-05/README.md``).

Outputs are held only on a frame whose singular gate switches the edge steps on, after a frame that did too
(``StreamState.edges``; a frame without them computes every pixel). Their work is what a held output saves; on a
frame without them (a still scene whose runs' means hide the sensor's flying pixels, or input without flying pixels)
a held output saves nothing and only freezes the pixel. And an output made while they did not act missed them for as
long as it was held once a mover's flying pixels switched them on: on the 2006 streams with a mover (``sensor``) the
stream had been 2 % worse than without held outputs (``docs/measurements/issue28-stream/twenty-eighth-stop/``).
"""
from __future__ import annotations

from dataclasses import replace
from typing import Optional

import torch
from torch import nn

from ..initial import InitialEstimate
from ..observation import Observation
from ..post_steps import run_steps
from ..state import RestorationState

__all__ = ["run_post_steps"]


def run_post_steps(steps: nn.ModuleList, x: torch.Tensor, state: RestorationState, obs: Observation,
                   initial: InitialEstimate, steady: Optional[torch.Tensor],
                   held: Optional[torch.Tensor]) -> torch.Tensor:
    """``steps`` on the layers' value ``x`` (B,1,H,W), except that ``steady`` pixels (B,1,H,W bool) take ``held``
    (the previous output, normalised as ``x``) and the edge steps skip them; the band then everywhere. ``steady``
    None: every step everywhere, as in a cold frame."""
    if steady is None:
        return run_steps(steps, x, state, obs, initial)
    local = replace(state, held=steady)  # the edge steps skip the steady pixels
    out = x
    for step in steps:
        if not _bounds(step):
            out = step(out, local, obs, initial)
    out = torch.where(steady, held.to(out), out)
    for step in steps:
        if _bounds(step):
            out = step(out, state, obs, initial)
    return out


def _bounds(step: nn.Module) -> bool:
    """Whether ``step`` is a do-no-harm bound on the output (``bounds_output``): it runs after the held pixels are
    pasted, on every pixel."""
    return getattr(step, "bounds_output", False)
