"""Issue 28, twenty-fourth stop (a finding about the model, not the stream): at the input's holes, is the restored
depth closer to the truth than x⁰, the colour-guided fill the layers start from?

Frame by frame (``restore_depth`` with the stream's model, ``denoise-fast``), on frames 10–29 of the three tuning
sequences: the RMSE at the holes of x⁰ (the initial stage's state, captured) and of the output, and the same over the
holes that lie within 3 px of a depth gap in the truth (a step of more than 10 % between 4-neighbours).

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-fourth-stop/holes_x0_vs_output.py --size 480x640
"""
from __future__ import annotations

import argparse

import cv2
import numpy as np
import torch

import torch_depth_sr.initial as initial
from torch_depth_sr import restore_depth
from torch_depth_sr.datasets.sequences import TUNING_SEQUENCES, make_sequence
from torch_depth_sr.stream import default_stream_model


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", default="480x640")
    a = p.parse_args()
    h, w = (int(t) for t in a.size.split("x"))
    torch.set_num_threads(1)
    shipped, caught = initial.DenoiseInit.forward, {}

    def forward(self, obs):
        out = shipped(self, obs)
        caught["x0"] = obs.denormalise(out.state.x)[0, 0].numpy().astype(np.float64)
        return out

    initial.DenoiseInit.forward = forward
    model = default_stream_model().eval()
    print(f"frame by frame at {a.size}, frames 10-29: RMSE at the input's holes (mm), x0 -> output")
    for spec in TUNING_SEQUENCES:
        seq = make_sequence(spec, frames=30, height=h, width=w)
        sums = np.zeros(4)
        counts = np.zeros(2)
        for t in range(10, 30):
            depth, gt = seq["depth"][t].astype(np.float32), seq["gt"][t, 0].astype(np.float64)
            with torch.no_grad():
                out = np.nan_to_num(restore_depth(depth, seq["rgb"][t], model=model)[0]).astype(np.float64)
            hole = depth[0] <= 0
            step = np.zeros_like(hole)
            step[:, 1:] |= np.abs(np.diff(gt, axis=1)) > 0.1 * gt[:, 1:]
            step[1:, :] |= np.abs(np.diff(gt, axis=0)) > 0.1 * gt[1:, :]
            near_gap = hole & (cv2.dilate(step.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0)
            for i, m in enumerate((hole, near_gap)):
                sums[2 * i] += ((caught["x0"] - gt) ** 2)[m].sum()
                sums[2 * i + 1] += ((out - gt) ** 2)[m].sum()
                counts[i] += m.sum()
        r = np.sqrt(sums / np.repeat(np.maximum(counts, 1), 2))
        print(f"  {spec.name:22s} holes {r[0]:7.1f} -> {r[1]:7.1f}   holes near a gap {r[2]:7.1f} -> {r[3]:7.1f}"
              f"   ({int(counts[0])} and {int(counts[1])} pixel-frames)")


if __name__ == "__main__":
    main()
