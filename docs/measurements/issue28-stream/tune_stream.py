"""Issue 28: the stream settings (config group ``stream``) for the trained ``fast`` tier, fitted on the TUNING
sequences only (``datasets.sequences.TUNING_SEQUENCES``: other seeds of the same recipes; the evaluated
``STREAM_SEQUENCES`` and the real recordings are never loaded here).

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/tune_stream.py [--model fast]

For every setting of the grid (change-test dilation, the run-mean cap ``max_frames``, the temporal prior's
``weight``): the stream's RMSE, flicker and trail on each tuning sequence divided by frame-by-frame restoration's.
A setting is admissible when its RMSE and trail ratios are at most 1 on every tuning sequence; among those the one
with the lowest mean flicker ratio is printed last. Prints a table; writes nothing.
"""
from __future__ import annotations

import argparse
import itertools

import numpy as np
import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.config import StreamConfig
from torch_depth_sr.datasets.sequences import TUNING_SEQUENCES, make_sequence
from torch_depth_sr.evaluation.stream import regions, synthetic_metrics
from torch_depth_sr.stream import StreamRestorer
from torch_depth_sr import restore_depth

GRID = {"dilate": (2, 3, 4), "max_frames": (8.0, 12.0, 16.0), "weight": (1.0, 2.0)}


def run(step, seq) -> np.ndarray:
    outs = []
    for t in range(seq["depth"].shape[0]):
        with torch.no_grad():
            outs.append(np.asarray(step(seq["depth"][t, 0], torch.from_numpy(seq["rgb"][t])[None]), np.float32))
    return np.stack(outs)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--model", default="fast")
    p.add_argument("--frames", type=int, default=30)
    a = p.parse_args()
    model = DepthRestorer.from_preset(a.model)
    seqs = [make_sequence(s, frames=a.frames, height=120, width=160) for s in TUNING_SEQUENCES]
    regs = [regions(s) for s in seqs]
    frame = [synthetic_metrics(run(lambda d, rgb: restore_depth(d, rgb, model=model), s), s, r)
             for s, r in zip(seqs, regs)]
    rows = []
    for dil, cap, w in itertools.product(GRID["dilate"], GRID["max_frames"], GRID["weight"]):
        settings = StreamConfig(dilate=dil, max_frames=cap, weight=w)
        ratios = []
        for s, r, f in zip(seqs, regs, frame):
            st = StreamRestorer(model, settings)
            m = synthetic_metrics(run(st.step, s), s, r)
            ratios.append([m["rmse"] / f["rmse"], m["flicker"] / f["flicker"], m["trail"] / f["trail"]])
        ratios = np.array(ratios)
        ok = bool((ratios[:, 0] <= 1).all() and (ratios[:, 2] <= 1).all())
        rows.append((dil, cap, w, ok, ratios[:, 1].mean(), ratios[:, 0].max(), ratios[:, 2].max()))
        print(f"dilate {dil} max_frames {cap:4.0f} weight {w:.0f}: flicker {ratios[:, 1].mean():.3f} "
              f"(max {ratios[:, 1].max():.3f}) rmse max {ratios[:, 0].max():.4f} trail max {ratios[:, 2].max():.4f}"
              f"{'' if ok else '  (not admissible)'}", flush=True)
    best = min((r for r in rows if r[3]), key=lambda r: r[4], default=None)
    print("chosen:", best)


if __name__ == "__main__":
    main()
