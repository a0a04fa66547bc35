"""Tried at the twenty-second stop, not shipped: x⁰'s colour-guided fill of a stream frame fed with the raw first
departures instead of the run's mean (docs/stream.md, "What holds the static-busy trail"). The stream holds a first
departure from a confident run out (the pixel keeps its run's mean); at a shadow band's rim beside a mover the fill
then sees the mover's depth on that side. Here, on a local patch of ``_Initial.guided`` (nothing in the package
changes): ``holes`` — the fill of the holes made from the raw departures, x⁰ elsewhere as shipped; ``all`` — the
whole colour-guided estimate (holes, guided prior, singular test's reference) made from them.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-second-stop/tried_fill_from_raw.py

The stream track's three synthetic sequences, the track's scores (mm) and frame-by-frame restoration's.
"""
from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "nineteenth-stop"))
from fresh_seeds import KEYS, restored_frames  # noqa: E402

from torch_depth_sr import initial, restore_depth  # noqa: E402
from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, make_sequence  # noqa: E402
from torch_depth_sr.evaluation.stream import regions, synthetic_metrics  # noqa: E402
from torch_depth_sr.stream import StreamRestorer, default_stream_model  # noqa: E402
from torch_depth_sr.stream import restorer  # noqa: E402

SHIPPED_JOIN, SHIPPED_GUIDED = restorer.join_runs, initial._Initial.guided
HELD_OUT: dict = {}


def patch(variant: str) -> None:
    restorer.join_runs, initial._Initial.guided = SHIPPED_JOIN, SHIPPED_GUIDED
    if variant == "shipped":
        return

    def join_runs(*a, **k):
        runs = SHIPPED_JOIN(*a, **k)
        HELD_OUT["map"] = runs.held_out
        return runs

    def guided(self, obs):
        est, confident = SHIPPED_GUIDED(self, obs)
        held_out = HELD_OUT.pop("map", None)
        if obs.temporal is None or held_out is None or not bool(held_out.any()):
            return est, confident
        raw = torch.where(held_out, obs.normalise(obs.raw), obs.y)
        est_raw, confident_raw = SHIPPED_GUIDED(self, replace(obs, y=raw))
        if variant == "all":
            return est_raw, confident_raw
        hole = obs.observed <= 0
        return torch.where(hole, est_raw, est), torch.where(hole, confident_raw, confident)

    restorer.join_runs, initial._Initial.guided = join_runs, guided


def main() -> None:
    torch.set_num_threads(1)
    model = default_stream_model()
    print("sequence        variant   " + "  ".join(f"{k:>8s}" for k in KEYS) + "   (frame by frame: " + ", ".join(KEYS) + ")")
    for spec in STREAM_SEQUENCES:
        seq = make_sequence(spec)
        reg = regions(seq)
        patch("shipped")
        base = synthetic_metrics(restored_frames(lambda d, c: restore_depth(d, c, model=model), seq), seq, reg)
        for variant in ("shipped", "holes", "all"):
            patch(variant)
            m = synthetic_metrics(restored_frames(StreamRestorer(model).step, seq), seq, reg)
            print(f"{spec.name:15s} {variant:8s}  " + "  ".join(f"{m[k]:8.2f}" for k in KEYS)
                  + "   (" + ", ".join(f"{base[k]:.2f}" for k in KEYS) + ")", flush=True)
    patch("shipped")


if __name__ == "__main__":
    main()
