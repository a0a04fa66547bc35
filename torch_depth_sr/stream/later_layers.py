"""The later layers of a stream frame update the fresh pixels only.

With ``StreamConfig.layers = n`` a frame with a past runs the model's first ``n`` layers on the whole frame; a static
pixel whose run has its full mean keeps that (the running mean and the temporal prior have done the later layers' work
there: ``docs/measurements/issue28-stream/layers_2006.txt``). A changed pixel has neither, and a young run too little
of the mean: these *fresh* pixels get the remaining layers. Each of those layers runs with the fresh pixels as its
``Observation.update_region``: its x-update solves for them alone (preconditioned by the operator's diagonal), with
every other pixel fixed at its value after the first layers, and every other pixel keeps its state. On the CPU the
singular test and the read of the matches are computed only where the fresh pixels read them
(:func:`~torch_depth_sr.singular.detect_singular`'s ``region``), so a layer costs the whole frame's element-wise work
plus the kernels on about the fresh pixels.

This replaced layers run on rectangles around the fresh pixels, padded by what the layers read: at 640×480 the
rectangles covered 62–69 % of a moving frame, and the fixed boundary came out more accurate than the padding
(``docs/measurements/issue28-stream/twenty-seventh-stop/``).
"""
from __future__ import annotations

from dataclasses import replace

import torch
from torch import nn

from ..observation import Observation
from ..state import RestorationState

__all__ = ["run_later_layers"]


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
    for layer in layers:
        state = layer(state, part)
    return state
