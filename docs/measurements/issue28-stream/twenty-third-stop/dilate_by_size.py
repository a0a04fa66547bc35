"""Issue 28, twenty-third stop: the change test's dilation (``StreamConfig.dilate``, px) at a frame size larger than
the stream track's 120×160, on fitting scenes, each against frame-by-frame restoration.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-third-stop/dilate_by_size.py --size 480x640 \
        --values 2 4 8 [--set tuning+300] [--processes 2]

``--set tuning+300``: the three tuning sequences and the three recipes with seeds 300–303 (15 of the 45 fitting
scenes; the evaluated sequences, seeds 1–3, are never loaded); ``--set fresh``: seeds 200–205 (18 scenes never used to
choose); ``--set evaluated``: the stream track's three sequences (reporting only). The stream model (``denoise-fast``) with each dilation, every other setting its own; per scene RMSE,
flicker and trail divided by frame-by-frame restoration's (the stream track's scores), then the mean, the worst and
the count of scenes that miss issue 28's targets (RMSE or trail above 1, flicker above 0.5).
"""
from __future__ import annotations

import argparse
import sys
from multiprocessing import Pool
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "nineteenth-stop"))
from fresh_seeds import KEYS, LIMITS, restored_frames  # noqa: E402  (the nineteenth stop's script)

from torch_depth_sr import restore_depth  # noqa: E402
from torch_depth_sr.datasets.sequences import (STREAM_SEQUENCES, TUNING_SEQUENCES, make_sequence,  # noqa: E402
                                               recipe_sequences)
from torch_depth_sr.evaluation.stream import regions, synthetic_metrics  # noqa: E402
from torch_depth_sr.stream import StreamRestorer, default_stream_model  # noqa: E402

SETS = {"tuning+300": lambda: [*TUNING_SEQUENCES, *recipe_sequences(range(300, 304))],
        "fresh": lambda: list(recipe_sequences(range(200, 206))),
        "evaluated": lambda: list(STREAM_SEQUENCES)}


def _scene(job) -> tuple[str, list]:
    spec, size, values = job
    torch.set_num_threads(1)
    model = default_stream_model()
    seq = make_sequence(spec, frames=30, height=size[0], width=size[1])
    reg = regions(seq)
    base = synthetic_metrics(restored_frames(lambda d, c: restore_depth(d, c, model=model), seq), seq, reg)
    rows = []
    for v in values:
        m = synthetic_metrics(restored_frames(StreamRestorer(model, {"dilate": v}).step, seq), seq, reg)
        rows.append([m[k] / base[k] for k in KEYS])
    return spec.name, rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", default="480x640")
    p.add_argument("--set", choices=tuple(SETS), default="tuning+300")
    p.add_argument("--values", nargs="+", type=int, default=[2, 8])
    p.add_argument("--processes", type=int, default=2)
    a = p.parse_args()
    size = tuple(int(t) for t in a.size.split("x"))
    with Pool(a.processes) as pool:
        results = pool.map(_scene, [(s, size, a.values) for s in SETS[a.set]()], chunksize=1)
    print(f"{a.set} at {a.size}, 30 frames")
    for name, rows in results:
        print(f"{name:22s} " + " | ".join(f"{v}: " + " ".join(f"{x:.4f}" for x in r) for v, r in zip(a.values, rows)))
    print("(rmse flicker trail, stream ÷ frame by frame)")
    for i, v in enumerate(a.values):
        r = np.array([rows[i] for _, rows in results])
        misses = [int((r[:, j] > LIMITS[k]).sum()) for j, k in enumerate(KEYS)]
        print(f"dilate {v}: mean " + " ".join(f"{k} {x:.4f}" for k, x in zip(KEYS, r.mean(0)))
              + " | worst " + " ".join(f"{x:.4f}" for x in r.max(0))
              + f" | scenes missing rmse/flicker/trail: {misses[0]}/{misses[1]}/{misses[2]} of {len(r)}")


if __name__ == "__main__":
    main()
