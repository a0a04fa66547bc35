"""Issue 28: a stream setting (``StreamConfig`` field ``--setting``) at several values on synthetic sequences, each
against frame-by-frame restoration.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/setting_synthetic.py --setting hold
        [--set fit|fresh|check|evaluated] [--values none 0.05 0.1 0.25] [--processes 2] [--rule lowest-trail]
        [--model default]

``--set fit``: the three tuning sequences and the three recipes with seeds 300–303 and 400–409 (45 scenes; the
evaluated sequences, seeds 1–3, are never loaded). ``--set fresh``: seeds 200–205; ``--set check``: seeds 500–505
(18 scenes each, never used to choose); ``--set evaluated``: the stream track's three sequences. The stream model
(``denoise-fast``; ``--model``: another) with each value, every other setting its own; per scene RMSE, flicker and
trail divided by frame-by-frame restoration's (the stream track's scores), then the mean and the worst of each and
the count of scenes that miss issue 28's targets (RMSE or trail above 1, flicker above 0.5). ``--rule lowest-trail``
(with ``--set fit`` and ``none`` among the values): among the values that leave no scene's RMSE above
frame-by-frame's and the mean flicker at most that of ``none``, the lowest mean trail (the twentieth stop's rule for
``shift_test``).
"""
from __future__ import annotations

import argparse
import sys
from multiprocessing import Pool
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent / "nineteenth-stop"))
from fresh_seeds import KEYS, LIMITS, restored_frames  # noqa: E402  (the nineteenth stop's script)

from torch_depth_sr import restore_depth  # noqa: E402
from torch_depth_sr.datasets.sequences import (STREAM_SEQUENCES, TUNING_SEQUENCES, make_sequence,  # noqa: E402
                                               recipe_sequences)
from torch_depth_sr.evaluation.stream import regions, synthetic_metrics  # noqa: E402
from torch_depth_sr.model import named_model  # noqa: E402
from torch_depth_sr.stream import StreamRestorer, default_stream_model  # noqa: E402

SETS = {"fit": lambda: [*TUNING_SEQUENCES, *recipe_sequences(range(300, 304)), *recipe_sequences(range(400, 410))],
        "fresh": lambda: list(recipe_sequences(range(200, 206))),
        "check": lambda: list(recipe_sequences(range(500, 506))),
        "evaluated": lambda: list(STREAM_SEQUENCES)}


def _scene(job) -> tuple[str, list]:
    spec, setting, values, model_name = job
    torch.set_num_threads(1)
    model = default_stream_model() if model_name is None else named_model(model_name)
    seq = make_sequence(spec, frames=30, height=120, width=160)
    reg = regions(seq)
    base = synthetic_metrics(restored_frames(lambda d, c: restore_depth(d, c, model=model), seq), seq, reg)
    rows = []
    for v in values:
        m = synthetic_metrics(restored_frames(StreamRestorer(model, {setting: v}).step, seq), seq, reg)
        rows.append([m[k] / base[k] for k in KEYS])
    return spec.name, rows


def main(setting: str = "hold", values: tuple = ("none", "0.1"), rule: str = "", doc: str = __doc__) -> None:
    p = argparse.ArgumentParser(description=doc)
    p.add_argument("--setting", default=setting, help="a field of StreamConfig")
    p.add_argument("--set", choices=tuple(SETS), default="fit")
    p.add_argument("--values", nargs="+", default=list(values), help="numbers, or none")
    p.add_argument("--processes", type=int, default=2)
    p.add_argument("--rule", choices=("", "lowest-trail"), default=rule)
    p.add_argument("--model", default=None, help="a preset or shipped model (default: the stream's, denoise-fast)")
    a = p.parse_args()
    values = [None if v == "none" else int(v) if v.isdigit() else float(v) for v in a.values]
    specs = SETS[a.set]()
    with Pool(a.processes) as pool:
        results = pool.map(_scene, [(s, a.setting, values, a.model) for s in specs], chunksize=1)
    for name, rows in results:
        print(f"{name:22s} " + " | ".join(f"{v}: " + " ".join(f"{x:.4f}" for x in r) for v, r in zip(values, rows)))
    print("(rmse flicker trail, stream ÷ frame by frame)")
    summary = {}
    for i, v in enumerate(values):
        r = np.array([rows[i] for _, rows in results])
        misses = [int((r[:, j] > LIMITS[k]).sum()) for j, k in enumerate(KEYS)]
        summary[v] = (r.mean(0), r.max(0), misses)
        print(f"{a.setting} {v}: mean " + " ".join(f"{k} {x:.4f}" for k, x in zip(KEYS, r.mean(0)))
              + "  worst " + " ".join(f"{x:.4f}" for x in r.max(0))
              + f"  misses rmse {misses[0]} flicker {misses[1]} trail {misses[2]} of {len(r)}")
    if a.rule == "lowest-trail" and a.set == "fit" and None in summary:
        flicker = summary[None][0][1]
        allowed = [v for v in values if v is not None and summary[v][2][0] == 0 and summary[v][0][1] <= flicker]
        print("chosen:", min(allowed, key=lambda v: summary[v][0][2]) if allowed else "none allowed")


if __name__ == "__main__":
    main()
