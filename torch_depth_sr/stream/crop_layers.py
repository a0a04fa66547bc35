"""The later layers of a stream frame run where the scene changed only: on crops around the changed pixels.

With ``StreamConfig.layers = n`` a frame with a past runs the model's first ``n`` layers on the whole frame; a static
pixel whose run has its full mean keeps that (the running mean and the temporal prior have done the later layers' work
there: ``docs/measurements/issue28-stream/layers_2006.txt``). A changed pixel has neither, and a young run too little
of the mean, so they get the remaining layers,
run on rectangles around the changed pixels (:func:`~torch_depth_sr.stream.matching.crops`) padded by what the
layers read around a pixel, and its values are pasted back from there. A crop is the model applied to a sub-image:
its CG step sizes and preconditioner are the crop's, not the whole frame's, so the values differ from a whole-frame
run by what that changes, not by a missing neighbour (the padding covers every pixel the layers read).

The crops need the observation, the state and the matches cut to them: a match that leaves its crop keeps its own
pixel with no weight (such pixels lie in the padding, whose values are not pasted). Layers that match again
(``Rematch``) or read a guidance network's features are not cut: with them the remaining layers run on the whole
frame.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Optional

import torch
from torch import nn

from ..guidance import NoGuidance
from ..native import host_path
from ..observation import Observation
from ..state import RestorationState
from ..terms import Rematch
from .matching import crop_matches, crops, search_radius

__all__ = ["run_later_layers"]

# the observation's per-pixel fields, cut with the crop (the others are per sample or shared)
_OBS_MAPS = ("y", "observed", "rgb", "raw", "glitches", "prior", "supported", "gate_region", "untrusted")
# the state's per-pixel fields, cut with the crop and pasted back where the scene changed
_STATE_MAPS = ("x", "z", "w", "e", "alpha", "q", "confidence")


def _cut(t: Optional[torch.Tensor], rows: slice, cols: slice) -> Optional[torch.Tensor]:
    return None if t is None else t[..., rows, cols]


def _cut_observation(obs: Observation, rows: slice, cols: slice) -> Observation:
    changes = {name: _cut(getattr(obs, name), rows, cols) for name in _OBS_MAPS}
    if obs.temporal is not None:
        changes["temporal"] = type(obs.temporal)(*(_cut(t, rows, cols) for t in obs.temporal))
    return replace(obs, **changes)


def _cut_state(s: RestorationState, rows: slice, cols: slice) -> RestorationState:
    width = s.x.shape[-1]
    changes = {name: _cut(getattr(s, name), rows, cols) for name in _STATE_MAPS}
    changes["matches"] = None if s.matches is None else crop_matches(s.matches, rows, cols, width, outside="own")
    return replace(s, **changes)


def _croppable(layers: nn.ModuleList, obs: Observation) -> bool:
    """Whether the remaining ``layers`` can run on crops: no re-matching, no guidance features, denoising."""
    return (obs.task == "denoise" and isinstance(obs.guidance, NoGuidance)
            and not any(isinstance(step, Rematch) for layer in layers for step in layer.steps[obs.task]))


def padding(obs: Observation, layers: int) -> int:
    """What ``layers`` layers read around a pixel, in pixels: per layer the matches' reach three times (the split
    steps read the matched values, the x-update's right-hand side and its operator do again) and the gradient's."""
    return layers * (3 * search_radius(obs.block_matcher.settings, obs.task) + 2)


def run_later_layers(layers: nn.ModuleList, state: RestorationState, obs: Observation,
                     changed: torch.Tensor) -> RestorationState:
    """``layers`` run where ``changed`` (B,1,H,W) bool: on crops around the changed pixels, whose values are pasted
    into ``state``; on the whole frame when the crops would cover most of it or the layers cannot be cut."""
    if len(layers) == 0 or not bool(changed.any()):
        return state
    h, w = state.x.shape[-2:]
    # off the CPU the whole frame: a GPU at these sizes is bound by kernel launches, which each crop repeats, and
    # finding the crops reads the changed pixels on the host (docs/measurements/h100-2026-12-05)
    cut = _croppable(layers, obs) and host_path(state.x.device)
    boxes = crops(changed, padding(obs, len(layers))) if cut else []
    area = sum((r.stop - r.start) * (c.stop - c.start) for r, c, _, _ in boxes)
    if not boxes or area >= 0.8 * h * w:
        whole = (slice(0, h), slice(0, w))
        boxes, cut = [(*whole, *whole)], False
    else:
        cut = True
    merged = {name: getattr(state, name).clone() for name in _STATE_MAPS}  # one copy, every crop pasted into it
    clean = state.clean
    for rows, cols, core_r, core_c in boxes:
        part, part_obs = (_cut_state(state, rows, cols), _cut_observation(obs, rows, cols)) if cut else (state, obs)
        for layer in layers:
            part = layer(part, part_obs)
        inner = (slice(core_r.start - rows.start, core_r.stop - rows.start),
                 slice(core_c.start - cols.start, core_c.stop - cols.start))
        mask = changed[..., core_r, core_c]
        for name, full in merged.items():
            full[..., core_r, core_c] = torch.where(mask, getattr(part, name)[..., inner[0], inner[1]],
                                                    full[..., core_r, core_c])
        # the singular gate's verdict of a sample holds where every run found it clean
        clean = part.clean if clean is None else (clean if part.clean is None else clean & part.clean)
    return replace(state, clean=clean, **merged)
