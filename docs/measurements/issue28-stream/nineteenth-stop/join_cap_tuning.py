"""Issue 28: the stream's ``join_cap`` (the bound on the noise unit a measurement is compared with to its run's mean)
fitted on an enlarged tuning set, and checked.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/nineteenth-stop/join_cap_tuning.py
        [--set tuning|fresh] [--values none 16 40 80 160]

``--set tuning``: the three tuning sequences and the three recipes with seeds 300–303 (15 scenes; the evaluated
sequences, seeds 1–3, are never loaded). ``--set fresh``: the recipes with seeds 200–205 (``fresh_seeds.py``).
The stream model (``denoise-fast``) with each value, every other setting its own; per scene RMSE, flicker and trail
divided by frame-by-frame restoration's (the stream track's scores), then the worst and the mean of each, and the
scenes where the stream's RMSE or trail exceeds frame-by-frame's. The rule (``--set tuning``): among the values that
leave no scene's RMSE above frame-by-frame's (do no harm) and whose mean flicker and trail are at most 0.5 % above
those without the bound (``none``; the eighteenth stop's rule for ``keep_scale``), the lowest mean RMSE.
"""
from __future__ import annotations

import argparse

import numpy as np
import torch
from tqdm import tqdm

from torch_depth_sr import restore_depth
from torch_depth_sr.datasets.sequences import TUNING_SEQUENCES, make_sequence, recipe_sequences
from torch_depth_sr.evaluation.stream import regions, synthetic_metrics
from torch_depth_sr.stream import StreamRestorer, default_stream_model

from fresh_seeds import KEYS, restored_frames  # this folder's script (its folder is on the path)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--set", choices=("tuning", "fresh"), default="tuning")
    p.add_argument("--values", nargs="+", default=["none", "16", "40", "80", "160"])
    a = p.parse_args()
    torch.set_num_threads(1)
    model = default_stream_model()
    specs = (recipe_sequences(range(300, 304)) + TUNING_SEQUENCES if a.set == "tuning"
             else recipe_sequences(range(200, 206)))
    values = [None if v == "none" else float(v) for v in a.values]
    ratios = {v: [] for v in values}
    for spec in tqdm(specs, desc="scenes"):
        seq = make_sequence(spec, frames=30, height=120, width=160)
        reg = regions(seq)
        base = synthetic_metrics(restored_frames(lambda d, c: restore_depth(d, c, model=model), seq), seq, reg)
        cells = []
        for v in values:
            m = synthetic_metrics(restored_frames(StreamRestorer(model, {"join_cap": v}).step, seq), seq, reg)
            ratios[v].append([m[k] / base[k] for k in KEYS])
            cells.append(f"{v}: " + " ".join(f"{x:.4f}" for x in ratios[v][-1]))
        tqdm.write(f"{spec.name:22s} " + " | ".join(cells))
    print("(rmse flicker trail, stream ÷ frame by frame)")
    means, worst = {}, {}
    for v, rows in ratios.items():
        r = np.array(rows)
        over = [f"{s.name} {r[i, 0]:.3f}/{r[i, 2]:.3f}" for i, s in enumerate(specs) if r[i, 0] > 1 or r[i, 2] > 1]
        means[v], worst[v] = r.mean(0), r.max(0)
        print(f"join_cap {v}: mean " + " ".join(f"{k} {x:.4f}" for k, x in zip(KEYS, r.mean(0)))
              + "  worst " + " ".join(f"{k} {x:.4f}" for k, x in zip(KEYS, r.max(0)))
              + f"  above 1 (rmse/trail): {', '.join(over) or 'none'}")

    if a.set == "tuning" and None in means:
        ok = [v for v in values if worst[v][0] <= 1 and all(means[v][i] <= 1.005 * means[None][i] for i in (1, 2))]
        print("chosen:", min(ok, key=lambda v: means[v][0]) if ok else "none of them")


if __name__ == "__main__":
    main()
