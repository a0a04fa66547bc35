"""The later layers of a stream frame update the fresh pixels only.

With ``StreamConfig.layers = n`` a frame with a past runs the model's first ``n`` layers on the whole frame; a static
pixel whose run has its full mean keeps that (the running mean and the temporal prior have done the later layers' work
there: ``docs/measurements/issue28-stream/layers_2006.txt``). A changed pixel has neither, and a young run too little
of the mean: these *fresh* pixels get the remaining layers. Each of those layers runs with the fresh pixels as its
``Observation.update_region``: its x-update solves for them alone (preconditioned by the operator's diagonal), with
every other pixel fixed at its value after the first layers, every other pixel keeps its state, and the singular gate
keeps its verdict. On the CPU the singular test and the read of the matches are computed only where the fresh pixels
read them (:func:`~torch_depth_sr.singular.detect_singular`'s ``region``).

What such a layer computes at a fresh pixel then depends only on the pixels within two match reaches and two pixels
of it. So where the fresh pixels are few (a still scene's noise, a small mover), the layers run on rectangles around
them padded by that much (:func:`~torch_depth_sr.stream.matching.crops`), the same values as on the whole frame up to
round-off, without the whole frame's element-wise work; where the rectangles would cover much of the frame, on the
whole frame.

This replaced layers run on rectangles padded by what two whole layers read (28 px at ``denoise-fast``): at 640×480
those covered 62–69 % of a moving frame, and the fixed boundary came out more accurate than the padding
(``docs/measurements/issue28-stream/twenty-seventh-stop/``).
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
from .matching import crop_matches, crops

__all__ = ["run_later_layers"]

# the observation's per-pixel fields, cut with a crop (the others are per sample or shared)
_OBS_MAPS = ("y", "observed", "rgb", "raw", "glitches", "prior", "supported", "gate_region", "untrusted",
             "update_region")
# the state's per-pixel fields, cut with a crop and pasted back at its fresh pixels
_STATE_MAPS = ("x", "z", "w", "e", "alpha", "q", "confidence")
_MOST = 0.25  # rectangles covering more of the frame than this: the whole frame (cheaper from there on)


def run_later_layers(layers: nn.ModuleList, state: RestorationState, obs: Observation,
                     fresh: torch.Tensor) -> RestorationState:
    """``layers`` updating the ``fresh`` pixels (B,1,H,W) bool of ``state`` alone."""
    if len(layers) == 0:
        return state
    # one host read, which spares work on any device: no fresh pixel skips the layers (a settled static scene), every
    # pixel fresh runs them as in a frame on its own (a moving camera)
    some, every = torch.stack([fresh.any(), fresh.all()]).tolist()
    if not some:
        return state
    part = replace(obs, update_region=None if every else fresh)
    boxes = None if every else _boxes(layers, state, part, fresh)
    if boxes is None:
        for layer in layers:
            state = layer(state, part)
        return state
    merged = {name: getattr(state, name).clone() for name in _STATE_MAPS}  # every crop pasted into one copy
    for rows, cols, core_r, core_c in boxes:
        s, o = _cut_state(state, rows, cols), _cut_observation(part, rows, cols)
        for layer in layers:
            s = layer(s, o)
        inner = (slice(core_r.start - rows.start, core_r.stop - rows.start),
                 slice(core_c.start - cols.start, core_c.stop - cols.start))
        mask = fresh[..., core_r, core_c]
        for name, full in merged.items():
            full[..., core_r, core_c] = torch.where(mask, getattr(s, name)[..., inner[0], inner[1]],
                                                    full[..., core_r, core_c])
    return replace(state, **merged)  # the gate's verdict and the matches stay the first layers'


def _boxes(layers: nn.ModuleList, state: RestorationState, obs: Observation, fresh: torch.Tensor) -> Optional[list]:
    """Rectangles around the fresh pixels padded by what a layer with an update region reads (two match reaches and
    two pixels), on the CPU, when they cover at most ``_MOST`` of the frame and the layers can be cut (denoising,
    no re-matching, no guidance features, the gate's verdict known); else None."""
    if not (host_path(fresh.device) and obs.task == "denoise" and state.matches is not None
            and all(_local(layer, obs) for layer in layers)):
        return None
    reach = obs.block_matcher.settings.window_and_k()[obs.task][0] // 2
    boxes = crops(fresh, 2 * reach + 2)
    h, w = fresh.shape[-2:]
    area = sum((r.stop - r.start) * (c.stop - c.start) for r, c, _, _ in boxes)
    return boxes if area <= _MOST * h * w else None


def _local(layer: nn.Module, obs: Observation) -> bool:
    return isinstance(obs.guidance, NoGuidance) and not any(isinstance(step, Rematch) for step in layer.steps[obs.task])


def _cut(t: Optional[torch.Tensor], rows: slice, cols: slice) -> Optional[torch.Tensor]:
    return None if t is None else t[..., rows, cols]


def _cut_observation(obs: Observation, rows: slice, cols: slice) -> Observation:
    changes = {name: _cut(getattr(obs, name), rows, cols) for name in _OBS_MAPS}
    if obs.temporal is not None:
        changes["temporal"] = type(obs.temporal)(*(_cut(t, rows, cols) for t in obs.temporal))
    return replace(obs, **changes)


def _cut_state(s: RestorationState, rows: slice, cols: slice) -> RestorationState:
    """``s`` on the crop; a match that leaves the crop keeps its own pixel with no weight (such pixels lie in the
    padding, whose values are not pasted back)."""
    changes = {name: _cut(getattr(s, name), rows, cols) for name in _STATE_MAPS}
    changes["matches"] = crop_matches(s.matches, rows, cols, s.x.shape[-1], outside="own")
    return replace(s, **changes)
