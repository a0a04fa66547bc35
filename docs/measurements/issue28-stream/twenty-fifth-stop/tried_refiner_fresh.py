"""Issue 28, twenty-fifth stop: does a stream step need the refiner beyond the fresh pixels? A patch of this process
(nothing here is shipped), run by the twenty-fourth stop's ``tried_variants.py`` (same scenes, same metrics: stream ÷
frame by frame).

On moving input the refiner runs on the whole frame (66–72 ms at 480×640) because the pixels not held are scattered:
the fresh ones (changed, or a young run: about 10 %) and static ones whose layers' value drifted by more than
``hold`` units (about 18 %). If the drifted ones did not need it, the refiner could run on crops around the fresh
pixels only.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-fifth-stop/tried_refiner_fresh.py --set fit \
        --size 120x160 --variants shipped refiner-fresh

Variants (besides those of ``tried_variants.py``), each in a stream step with a past, then the band as shipped:

* ``refiner-fresh`` — the refiner's output is taken at the fresh pixels only; every other pixel keeps the value
  before the refiner (the edge steps' output);
* ``refiner-kept`` — the same at the fresh pixels; every other pixel takes the value before the refiner plus the
  refiner's correction as it was last computed there (in the first frame, or the last frame it was fresh).
"""
from __future__ import annotations

import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "twenty-fourth-stop"))
import tried_variants as tv  # noqa: E402  (the twenty-fourth stop's script: scenes, metrics, report)

import torch_depth_sr.stream.frame as frame  # noqa: E402
from torch_depth_sr.post_steps import DenoiseRefineStep  # noqa: E402

SHIPPED = (frame.StreamFrame.post, DenoiseRefineStep.forward)
_SHIPPED_USE = tv.use
FRESH: dict = {}  # the stream frame's fresh pixels while its post-steps run
KEPT: dict = {}  # the refiner's last correction per pixel (refiner-kept), for the one stream this process runs


def post_noting_fresh(self, steps, x, state, obs, initial):
    FRESH["mask"] = self.fresh if self.warm else None
    FRESH["stream"] = True
    try:
        return SHIPPED[0](self, steps, x, state, obs, initial)
    finally:
        FRESH.clear()


def refine_at_fresh(self, x, state, obs, initial):
    out = SHIPPED[1](self, x, state, obs, initial)
    fresh = FRESH.get("mask")
    return out if fresh is None else torch.where(fresh, out, x)


def refine_kept(self, x, state, obs, initial):
    out = SHIPPED[1](self, x, state, obs, initial)
    if "stream" not in FRESH:  # a frame-by-frame restoration
        return out
    fresh = FRESH.get("mask")
    correction = out - x
    if fresh is not None and "correction" in KEPT:
        correction = torch.where(fresh, correction, KEPT["correction"].to(correction))
    KEPT["correction"] = correction
    return x + correction


def use(variant: str) -> None:
    _SHIPPED_USE("shipped")
    frame.StreamFrame.post, DenoiseRefineStep.forward = SHIPPED
    FRESH.clear()
    KEPT.clear()
    if variant == "refiner-fresh":
        frame.StreamFrame.post, DenoiseRefineStep.forward = post_noting_fresh, refine_at_fresh
    elif variant == "refiner-kept":
        frame.StreamFrame.post, DenoiseRefineStep.forward = post_noting_fresh, refine_kept
    else:
        _SHIPPED_USE(variant)


tv.use = use

if __name__ == "__main__":
    tv.main()
