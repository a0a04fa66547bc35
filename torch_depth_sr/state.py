"""What the unrolled iterations carry: the iterates (:class:`RestorationState`), what stays fixed during one
forward (:class:`RestorationContext`) and what a forward records about itself (:class:`RunLog`, :func:`stage`).

The state holds the iterates only, so ``dataclasses.replace`` of a state shares nothing mutable with the new one;
the CG iteration counts and the stage timings go to the context's run log, one per forward.
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Iterator, Optional, Protocol

import torch

from .block_matching import BlockMatches
from .guidance import PreparedGuidance
from .operators import Degradation

__all__ = ["Matcher", "RestorationContext", "RestorationState", "RunLog", "stage"]


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


class Matcher(Protocol):
    """What the layers need of a block matcher (:class:`~torch_depth_sr.stages.BlockMatcher` implements it; this
    module only names the interface, so it does not import the stages that use it)."""

    def scheduled(self, index: int) -> bool:
        """Whether layer ``index`` matches again."""
        ...

    def __call__(self, x: torch.Tensor, ctx: "RestorationContext", q: torch.Tensor,
                 previous: Optional[BlockMatches] = None) -> BlockMatches:
        """The matches of ``x`` (untrusted pixels ``q`` = 0 masked when ``K = I``)."""
        ...


@dataclass
class RestorationContext:
    """What stays fixed during the unrolled iterations: the observation, the guide and the degradation ``K``; and
    the forward's :class:`RunLog`."""

    y: torch.Tensor  # (B,1,h,w) normalised observation, 0 where missing
    observed: torch.Tensor  # (B,1,h,w)
    rgb: Optional[torch.Tensor]  # (B,3,H,W)
    K: Degradation  # from the output grid (H,W) to the observation grid (h,w); Identity when they are one
    # the model's one block matcher (its settings, the temperature h and the colour weight ρ): x⁰'s matches and
    # every scheduled layer's go through it
    block_matcher: "Matcher"
    prior: Optional[torch.Tensor] = None  # (B,1,H,W) guided estimate that untrusted pixels are pulled to (K = I)
    grid_step: Optional[torch.Tensor] = None  # (B,) quantisation step of y in its normalised units (0 = none)
    lowres: Optional[torch.Tensor] = None  # (B,1,h,w) the filled estimate x⁰ was upsampled from (K ≠ I)
    fill_confident: Optional[torch.Tensor] = None  # (B,1,h,w) {0,1}: measured, or a hole filled from a clear side
    # (B,1,h,w) bool: measured pixels with enough agreeing measured neighbours (SingularConfig.support), which
    # the singular test always trusts; depends on y only, so the first test computes it (supported_pixels)
    supported: Optional[torch.Tensor] = None
    # (B,1,1,1) bool: samples the last singular test's gate found free of singular pixels (None before a test)
    clean: Optional[torch.Tensor] = None
    # the guidance network with this forward's colour features (RestorerConfig.guidance_net), or None
    guidance: Optional[PreparedGuidance] = None
    log: RunLog = field(default_factory=RunLog)  # CG iterations and stage timings of this forward
