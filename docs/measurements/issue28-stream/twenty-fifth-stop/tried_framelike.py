"""Issue 28, twenty-fifth stop: is the stream's longer trail made near the movers? Variants that make the stream's
inputs frame-by-frame's within R px of a changed pixel, each as a patch of this process (nothing here is shipped),
run by the twenty-fourth stop's ``tried_variants.py`` (same scenes, same metrics: stream ÷ frame by frame).

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-fifth-stop/tried_framelike.py --set tuning \
        --size 480x640 --variants shipped framelike4 framelike12 fresh-matches

Variants (besides those of ``tried_variants.py``):

* ``framelikeR`` — within R px of a changed pixel the model reads this frame's measurement (no run's mean, nothing
  held out or dropped as an outlier in time), no temporal prior, the singular gate reads the pixel, and the later
  layers run there (the holes' fill verdicts stay the stream's);
* ``fresh-matches`` — no previous match kept anywhere (every pixel searched again, as frame by frame);
* ``fresh-policy`` — the observation's offset, scale and noise level estimated again in every frame (as frame by
  frame), not kept from the previous frame while half of it was static (``keep_scale``).

If the trail stays longer than frame by frame's with everything near the movers frame-like, the excess comes from
farther away (the x⁰ fill, the noise level, the matches of the static parts).
"""
from __future__ import annotations

import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "twenty-fourth-stop"))
import tried_variants as tv  # noqa: E402  (the twenty-fourth stop's script: scenes, metrics, report)

import torch_depth_sr.stream.frame as frame  # noqa: E402
from torch_depth_sr.stream.matching import dilate  # noqa: E402

SHIPPED = (frame.join_runs, frame.StreamMatcher, frame.StreamFrame.scale_policy)
_SHIPPED_USE = tv.use


def framelike_join(radius, y, observed, static, *args):
    """``join_runs`` as shipped, then frame-by-frame's inputs within ``radius`` px of a changed pixel."""
    runs = SHIPPED[0](y, observed, static, *args)
    near = dilate(~static, radius)
    no = torch.zeros_like(near)
    return runs._replace(y=torch.where(near, y, runs.y), observed=torch.where(near, observed, runs.observed),
                         outlier=torch.where(near, no, runs.outlier), held_out=torch.where(near, no, runs.held_out),
                         averaged=torch.where(near, no, runs.averaged),
                         weight=torch.where(near, torch.zeros_like(runs.weight), runs.weight),
                         fresh=runs.fresh | near)


def use(variant: str) -> None:
    _SHIPPED_USE("shipped")  # the twenty-fourth stop's patches undone first (it sets frame.join_runs too)
    frame.join_runs, frame.StreamMatcher, frame.StreamFrame.scale_policy = SHIPPED
    if variant.startswith("framelike"):
        radius = int(variant[9:])
        frame.join_runs = lambda y, observed, static, *a: framelike_join(radius, y, observed, static, *a)
    elif variant == "fresh-matches":
        frame.StreamMatcher = lambda inner, *a: inner
    elif variant == "fresh-policy":
        frame.StreamFrame.scale_policy = lambda self, *a: None
    else:
        _SHIPPED_USE(variant)


tv.use = use

if __name__ == "__main__":
    tv.main()
