"""Issue 28: the stream settings (config group ``stream``) for the trained ``fast`` tier, fitted on the TUNING
sequences only (``datasets.sequences.TUNING_SEQUENCES``: other seeds of the same recipes; the evaluated
``STREAM_SEQUENCES`` and the real recordings are never loaded here).

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/tune_stream.py [--model denoise-fast]

For every setting of the grid (change-test dilation, the run-mean cap ``max_frames``, the temporal prior's
``weight``): the stream's RMSE, flicker and trail on each tuning sequence divided by frame-by-frame restoration's.
A setting is admissible when its RMSE and trail ratios are at most 1 on every tuning sequence; among those the one
with the lowest mean flicker ratio is printed last.

Then, at that setting, the layers a frame with a previous frame runs (``layers``: the first 1, 2 or all of the
model's): among the admissible ones whose mean flicker ratio is within 0.01 of the lowest, the fewest (the cheapest
step; issue 28's step target). ``--layers-only`` skips the first grid and starts from the shipped setting
(dilate 2, max_frames 8, weight 0.5; fitted by ``fit_stream_2006.py``). The tuning sequences do not show what fewer layers cost where the scene
changed (``cold_layers_2006.py``): no tier ships with the count chosen here. Prints a table; writes nothing.
"""
from __future__ import annotations

import argparse
import itertools

import numpy as np
import torch

from torch_depth_sr.model import named_model
from torch_depth_sr.config import StreamConfig
from torch_depth_sr.datasets.sequences import TUNING_SEQUENCES, make_sequence
from torch_depth_sr.evaluation.stream import regions, synthetic_metrics
from torch_depth_sr.stream import StreamRestorer
from torch_depth_sr import restore_depth

GRID = {"dilate": (2, 3, 4), "max_frames": (8.0, 12.0, 16.0), "weight": (1.0, 2.0)}
LAYERS = (1, 2, None)


def run(step, seq) -> np.ndarray:
    outs = []
    for t in range(seq["depth"].shape[0]):
        with torch.no_grad():
            outs.append(np.asarray(step(seq["depth"][t, 0], torch.from_numpy(seq["rgb"][t])[None]), np.float32))
    return np.stack(outs)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--model", default="denoise-fast", help="a preset or shipped model (default: the stream's)")
    p.add_argument("--frames", type=int, default=30)
    p.add_argument("--layers-only", action="store_true")
    a = p.parse_args()
    model = named_model(a.model)
    seqs = [make_sequence(s, frames=a.frames, height=120, width=160) for s in TUNING_SEQUENCES]
    regs = [regions(s) for s in seqs]
    frame = [synthetic_metrics(run(lambda d, rgb: restore_depth(d, rgb, model=model), s), s, r)
             for s, r in zip(seqs, regs)]

    def score(settings: StreamConfig) -> tuple[bool, np.ndarray]:
        ratios = []
        for s, r, f in zip(seqs, regs, frame):
            m = synthetic_metrics(run(StreamRestorer(model, settings).step, s), s, r)
            ratios.append([m["rmse"] / f["rmse"], m["flicker"] / f["flicker"], m["trail"] / f["trail"]])
        ratios = np.array(ratios)
        return bool((ratios[:, 0] <= 1).all() and (ratios[:, 2] <= 1).all()), ratios

    def line(ok: bool, ratios: np.ndarray) -> str:
        return (f"flicker {ratios[:, 1].mean():.3f} (max {ratios[:, 1].max():.3f}) rmse max {ratios[:, 0].max():.4f} "
                f"trail max {ratios[:, 2].max():.4f}{'' if ok else '  (not admissible)'}")

    best = (2, 8.0, 0.5)
    if not a.layers_only:
        rows = []
        for dil, cap, w in itertools.product(GRID["dilate"], GRID["max_frames"], GRID["weight"]):
            ok, ratios = score(StreamConfig(dilate=dil, max_frames=cap, weight=w))
            rows.append((dil, cap, w, ok, ratios[:, 1].mean(), ratios[:, 0].max(), ratios[:, 2].max()))
            print(f"dilate {dil} max_frames {cap:4.0f} weight {w:.0f}: {line(ok, ratios)}", flush=True)
        chosen = min((r for r in rows if r[3]), key=lambda r: r[4], default=None)
        print("chosen:", chosen)
        if chosen is None:
            return
        best = chosen[:3]
    dil, cap, w = best
    rows = []
    for n in LAYERS:
        ok, ratios = score(StreamConfig(dilate=dil, max_frames=cap, weight=w, layers=n))
        rows.append((n, ok, ratios[:, 1].mean()))
        print(f"dilate {dil} max_frames {cap:g} weight {w:g} layers {n or 'all'}: {line(ok, ratios)}", flush=True)
    admissible = [r for r in rows if r[1]]
    if admissible:
        low = min(r[2] for r in admissible)
        near = [r for r in admissible if r[2] <= low + 0.01]
        print("chosen layers:", min(near, key=lambda r: r[0] or len(model.layers))[0] or "all")


if __name__ == "__main__":
    main()
