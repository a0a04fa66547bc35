"""Tried at the twenty-second stop, not shipped: x⁰'s colour-guided fill of a stream frame fed with measurements the
stream keeps from the model (docs/stream.md, "What holds the static-busy trail"). The stream holds a first departure
from a confident run out (the pixel keeps its run's mean) and drops an outlier in time (the pixel is a hole this
frame); at a shadow band's rim beside a mover the band's fill then sees the mover's depth on that side only. A local
patch of ``_Initial.guided`` (nothing in the package changes) makes the colour-guided estimate again from the frame
with those measurements put back, and uses it where the variant says:

* ``shipped`` — no patch;
* ``departures@holes`` — the held-out departures put back, the estimate used at the model's holes;
* ``departures@all`` — the same, the estimate used everywhere (holes, guided prior, singular test's reference);
* ``outliers@sensor-holes`` — the dropped outliers put back (as measured pixels), the estimate used at the sensor's
  own holes only (not at the dropped pixels);
* ``outliers+departures@sensor-holes`` — both put back, the same pixels;
* ``rim-outliers@sensor-holes`` — only the dropped outliers next to a sensor hole (3×3) put back;
* ``far-outliers@sensor-holes`` / ``near-outliers@sensor-holes`` — only the dropped outliers farther / nearer than the
  previous estimate put back.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-second-stop/tried_fill_from_raw.py --set evaluated
    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-second-stop/tried_fill_from_raw.py --set fit

Per set: each variant's RMSE, flicker and trail divided by frame-by-frame restoration's (the stream track's scores),
the mean and the worst, and the scenes that miss issue 28's targets; ``--set evaluated`` also prints the stream's own
figures (mm). The sets are ``setting_synthetic.py``'s.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from multiprocessing import Pool
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "nineteenth-stop"))
from fresh_seeds import KEYS, LIMITS, restored_frames  # noqa: E402
from setting_synthetic import SETS  # noqa: E402

from torch_depth_sr import initial, restore_depth  # noqa: E402
from torch_depth_sr.datasets.sequences import make_sequence  # noqa: E402
from torch_depth_sr.evaluation.stream import regions, synthetic_metrics  # noqa: E402
from torch_depth_sr.stream import StreamRestorer, default_stream_model  # noqa: E402
from torch_depth_sr.stream import frame  # noqa: E402

VARIANTS = ("shipped", "departures@holes", "departures@all", "outliers@sensor-holes",
            "outliers+departures@sensor-holes", "rim-outliers@sensor-holes", "far-outliers@sensor-holes",
            "near-outliers@sensor-holes")
SHIPPED_JOIN, SHIPPED_GUIDED = frame.join_runs, initial._Initial.guided
KEPT: dict = {}


def patch(variant: str) -> None:
    frame.join_runs, initial._Initial.guided = SHIPPED_JOIN, SHIPPED_GUIDED
    if variant == "shipped":
        return
    put, where = variant.split("@")

    def join_runs(y, observed, *a, **k):
        runs = SHIPPED_JOIN(y, observed, *a, **k)
        back = torch.zeros_like(runs.held_out)
        if "departures" in put:
            back = back | runs.held_out
        if "outliers" in put:
            out = runs.outlier
            if put.startswith("rim"):
                out = out & (F.max_pool2d((observed <= 0).float(), 3, 1, 1) > 0)
            back = back | out
        KEPT.update(back=back, sensor_hole=observed <= 0)
        return runs

    def guided(self, obs):
        est, confident = SHIPPED_GUIDED(self, obs)
        back = KEPT.pop("back", None)
        if obs.temporal is not None and back is not None and put.startswith(("far", "near")):
            farther = obs.normalise(obs.raw) > obs.temporal.target
            back = back & (farther if put.startswith("far") else ~farther)
        if obs.temporal is None or back is None or not bool(back.any()):
            return est, confident
        y = torch.where(back, obs.normalise(obs.raw), obs.y)
        observed = torch.where(back, torch.ones_like(obs.observed), obs.observed)
        est_b, confident_b = SHIPPED_GUIDED(self, replace(obs, y=y, observed=observed))
        if where == "all":
            return est_b, confident_b
        at = KEPT["sensor_hole"] if where == "sensor-holes" else obs.observed <= 0
        return torch.where(at, est_b, est), torch.where(at, confident_b, confident)

    frame.join_runs, initial._Initial.guided = join_runs, guided


def scene(spec) -> tuple[str, list, list]:
    torch.set_num_threads(1)
    model = default_stream_model()
    seq = make_sequence(spec, frames=30, height=120, width=160)
    reg = regions(seq)
    patch("shipped")
    base = synthetic_metrics(restored_frames(lambda d, c: restore_depth(d, c, model=model), seq), seq, reg)
    ratios, absolute = [], []
    for v in VARIANTS:
        patch(v)
        m = synthetic_metrics(restored_frames(StreamRestorer(model).step, seq), seq, reg)
        ratios.append([m[k] / base[k] for k in KEYS])
        absolute.append([m[k] for k in KEYS] + [base[k] for k in KEYS])
    patch("shipped")
    return spec.name, ratios, absolute


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--set", choices=tuple(SETS), default="evaluated")
    p.add_argument("--processes", type=int, default=2)
    a = p.parse_args()
    specs = SETS[a.set]()
    with Pool(a.processes) as pool:
        res = pool.map(scene, specs, chunksize=1)
    r = np.array([rows for _, rows, _ in res])  # (scenes, variants, 3)
    print(f"set {a.set}, {len(specs)} scenes; ratios to frame by frame: mean (worst), misses")
    for i, v in enumerate(VARIANTS):
        misses = [int((r[:, i, j] > LIMITS[k]).sum()) for j, k in enumerate(KEYS)]
        print(f"{v:34s} " + "  ".join(f"{k} {r[:, i, j].mean():.4f} ({r[:, i, j].max():.4f})" for j, k in enumerate(KEYS))
              + "  misses " + "/".join(map(str, misses)))
    if a.set == "evaluated":
        print("\nper sequence (mm): stream " + ", ".join(KEYS) + "  (frame by frame)")
        for name, _, absolute in res:
            for v, row in zip(VARIANTS, absolute):
                print(f"{name:15s} {v:34s} " + " ".join(f"{x:8.2f}" for x in row[:3])
                      + "   (" + ", ".join(f"{x:.2f}" for x in row[3:]) + ")")


if __name__ == "__main__":
    main()
