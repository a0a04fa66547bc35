"""Issue 28, twenty-fourth stop: where a stream's RMSE exceeds frame-by-frame restoration's on a fitting scene.

``tune-pan-then-hold`` at 480×640 is the one fitting scene whose RMSE stays above frame-by-frame's with the gate fixed
(1.019). Both are run on it; from the first frame after the camera stops (the change test's first static frame, one
after ``hold_from``) the difference of squared errors, ``e_stream² − e_frame²``, is summed over groups of pixels and
divided by the pixel count of those frames: each row is that group's share of the difference of the two mean squared
errors. Groups (from the stream's runs, :func:`~torch_depth_sr.stream.runs.join_runs`, and its state before the
frame): measured pixels held out as a first departure, dropped as outliers in time, restarted, averaged into their
run; holes filled from a confident past, holes that were holes in the previous frame too (their fill is the frame's
own, pulled towards the previous output), holes measured before; changed pixels.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-fourth-stop/rmse_excess.py

Fitting scenes only (it reads ground truth to score, which the stream never does).
"""
from __future__ import annotations

import argparse
from collections import defaultdict

import numpy as np
import torch

import torch_depth_sr.stream.frame as frame
from torch_depth_sr import restore_depth
from torch_depth_sr.datasets.sequences import TUNING_SEQUENCES, make_sequence
from torch_depth_sr.stream import StreamRestorer, default_stream_model


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sequence", default="tune-pan-then-hold", choices=[s.name for s in TUNING_SEQUENCES])
    p.add_argument("--size", default="480x640")
    a = p.parse_args()
    h, w = (int(t) for t in a.size.split("x"))
    torch.set_num_threads(1)
    seq = make_sequence(next(s for s in TUNING_SEQUENCES if s.name == a.sequence), frames=30, height=h, width=w)
    shipped, caught = frame.join_runs, {}

    def join_runs(*args):
        caught["runs"] = shipped(*args)
        return caught["runs"]

    frame.join_runs = join_runs
    model = default_stream_model().eval()
    stream = StreamRestorer(model)
    gt = seq["gt"][:, 0].astype(np.float64)
    sums: dict = defaultdict(float)
    pixels = 0
    with torch.no_grad():
        for t in range(len(gt)):
            depth, rgb = seq["depth"][t].astype(np.float32), seq["rgb"][t]
            before = stream.state
            evidence = None if before is None else before.evidence[0, 0].numpy().copy()
            was_hole = None if before is None else before.hole[0, 0].numpy().copy()
            caught.clear()
            s = stream.step(depth, rgb, return_details=True)
            f = restore_depth(depth, rgb, model=model)
            if t <= seq["hold_from"]:
                continue
            runs = {k: getattr(caught["runs"], k)[0, 0].numpy() for k in ("held_out", "outlier", "restarted",
                                                                          "averaged")}
            diff = (np.nan_to_num(s.depth[0]) - gt[t]) ** 2 - (np.nan_to_num(f[0]) - gt[t]) ** 2
            hole, static = depth[0] <= 0, s.static[0] > 0
            from_past = hole & static & (evidence >= stream.settings.fill_evidence)
            groups = {"all": np.ones_like(hole), "held out": runs["held_out"], "outlier in time": runs["outlier"],
                      "restarted": runs["restarted"], "averaged": runs["averaged"] & ~runs["held_out"],
                      "hole, filled from the past": from_past, "hole, a hole before too": hole & ~from_past & was_hole,
                      "hole, measured before": hole & ~from_past & ~was_hole, "changed": ~static}
            for name, mask in groups.items():
                sums[name] += diff[mask].sum()
                sums["n " + name] += mask.sum()
            pixels += diff.size
    print(f"{a.sequence} at {a.size}, frames {seq['hold_from'] + 1}-{len(gt) - 1}: share of the MSE difference "
          "(stream − frame by frame), mm², by group (pixel-frames)")
    for name in [k for k in sums if not k.startswith("n ")]:
        print(f"  {name:28s} {sums[name] / pixels:+9.2f}   ({int(sums['n ' + name])})")


if __name__ == "__main__":
    main()
