"""Issue 28: where a steady ``stream-fast`` step goes, part by part (wall time of wrapped functions; parts nest).

    python docs/measurements/issue28-stream/step_parts.py [--size 480x640] [--steps 12] [--threads 2]

The speed track's stream (``evaluation.speed``: ``denoise-fast``, a static scene with new noise each step); the
means over ``--steps`` steps after 9 warm-up steps (every run full). Indented rows are inside the row above them.
"""
from __future__ import annotations

import argparse
import collections
import time

import torch

import torch_depth_sr.initial as initial
import torch_depth_sr.model as model
import torch_depth_sr.post_steps as post
import torch_depth_sr.stream.change as change
import torch_depth_sr.stream.frame as frame
from torch_depth_sr.evaluation.speed import _make_runner, make_inputs

PARTS = [  # (module or class, function, label)
    (model, "observe", "observation (scale, noise)"),
    (frame.StreamFrame, "observe", "stream: change test and runs"),
    (frame, "change_test", "  change test"),
    (change, "_nearest_distance", "    nearest previous value"),
    (change, "depth_votes", "    depth votes"),
    (change, "colour_changes", "    colour change"),
    (change, "camera_moved", "    camera test"),
    (change, "dilate", "    dilations"),
    (frame, "join_runs", "  runs joined"),
    (frame.StreamFrame, "initial", "x⁰"),
    (initial.DenoiseInit, "guided", "  colour-guided fill"),
    (initial, "domain_transform_filter", "    domain transform"),
    (initial, "fill_holes_sided", "    sided fill"),
    (initial, "_alpha", "  α⁰"),
    (frame.StreamFrame, "run_layers", "layers"),
    (post.RefineStep, "forward", "edge refiner"),
    (frame.StreamFrame, "keep", "stream: state kept"),
    (frame, "remembered_spread", "  noise unit"),
    (frame, "grow_runs", "  runs grown"),
]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--size", default="480x640")
    p.add_argument("--steps", type=int, default=12)
    p.add_argument("--threads", type=int, default=2)
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    spent: dict = collections.defaultdict(float)
    for owner, name, label in PARTS:
        f = getattr(owner, name)

        def timed(*args, _f=f, _label=label, **kw):
            t0 = time.perf_counter()
            out = _f(*args, **kw)
            spent[_label] += time.perf_counter() - t0
            return out

        setattr(owner, name, timed)
    h, w = map(int, a.size.split("x"))
    y, rgb, _ = make_inputs(h, w, 1)
    step = _make_runner("stream-fast", "cpu")
    total = 0.0
    with torch.no_grad():
        for _ in range(9):
            step(y, rgb)
        spent.clear()
        for _ in range(a.steps):
            t0 = time.perf_counter()
            step(y, rgb)
            total += time.perf_counter() - t0
    print(f"{h}x{w}, {a.threads} threads, mean of {a.steps} steady steps (ms)")
    for _, _, label in PARTS:
        print(f"{label:34s} {1000 * spent[label] / a.steps:7.1f}")
    print(f"{'step':34s} {1000 * total / a.steps:7.1f}")


if __name__ == "__main__":
    main()
