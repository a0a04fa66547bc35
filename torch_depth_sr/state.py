"""What the unrolled iterations carry (:class:`RestorationState`) and what a forward records about itself
(:class:`RunLog`, :func:`stage`). What stays fixed during one forward is the
:class:`~torch_depth_sr.observation.Observation`.

The state holds the iterates only, so ``dataclasses.replace`` of a state shares nothing mutable with the new one;
the CG iteration counts and the stage timings go to the observation's run log, one per forward.
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Iterator, Optional

import torch

from .block_matching import BlockMatches

__all__ = ["RestorationState", "RunLog", "stage"]


@dataclass
class RestorationState:
    """The iterates carried from layer to layer (all in normalised units), nothing else."""

    x: torch.Tensor  # (B,1,H,W) estimate on the output grid
    z: torch.Tensor  # (B,2,H,W)
    w: torch.Tensor  # (B,2,H,W)
    e: torch.Tensor  # (B,1,h,w) outliers on the observation grid
    alpha: torch.Tensor  # (B,2,H,W)
    q: torch.Tensor  # (B,1,h,w) {0,1} trusted pixels
    confidence: torch.Tensor  # (B,1,h,w) in [0,1]
    matches: Optional[BlockMatches]  # weights included (differentiable in the temperature)
    # (B,1,1,1) bool: samples the last singular test's gate found free of singular pixels (None before a gated test);
    # the terms read it as a per-sample weight (CleanSamples), the edge steps act on the other samples
    clean: Optional[torch.Tensor] = None
    # (B,1,H,W) bool: pixels whose output a stream holds from its previous frame (stream/post_hold.py); the edge steps
    # do not compute them (None: none)
    held: Optional[torch.Tensor] = None


@dataclass
class RunLog:
    """What one forward records about itself: the CG iteration counts of each solve and, when timed, the wall time
    of each stage."""

    cg_iterations: list = field(default_factory=list)  # per solve, a (B,) int64 tensor (read only when reported)
    timings: Optional[dict] = None  # seconds per stage, accumulated over layers; None = not timed


@contextmanager
def stage(timings: Optional[dict], name: str, device: torch.device) -> Iterator[None]:
    """Accumulate the wall time of a stage into ``timings``; with ``timings=None`` nothing is timed.

    Timing synchronises CUDA before and after the stage (so the time is real), which a forward that is not
    timed must not do: the host would wait for the device at every stage.
    """
    with torch.profiler.record_function(f"stage:{name}"):  # a no-op unless a profiler is running
        if timings is None:
            yield
            return
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        t0 = time.perf_counter()
        yield
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        timings[name] = timings.get(name, 0.0) + time.perf_counter() - t0
