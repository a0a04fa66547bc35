"""Issue 28: a stream step of a tier against a cold frame of the same tier, the two called in turn in one process.

    python docs/measurements/issue28-stream/step_vs_cold.py [--tier denoise-fast] [--layers 1|all] [--threads 2]
        [--sizes 370x463 480x640 1088x1376] [--rounds 5]

The speed track's inputs (``evaluation.speed.make_inputs``: a static synthetic scene, σ = 5, the same holes every
frame, new noise each call). The stream first runs its cold frame and 3 steps; then each round times one step and one
cold frame of the tier on the same new frame. Prints the minimum and the median of the rounds and the ratio of the
minima. ``--layers`` overrides the stream's ``layers`` (default: the tier's own). Run it with and without
``MALLOC_MMAP_THRESHOLD_=4294967296 MALLOC_TRIM_THRESHOLD_=4294967296`` to see what glibc's returning of freed
memory to the system costs (docs/speed.md).
"""
from __future__ import annotations

import argparse
import statistics
import time

import torch

from torch_depth_sr.model import named_model
from torch_depth_sr.evaluation.speed import make_inputs
from torch_depth_sr.stream import StreamRestorer


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--tier", default="denoise-fast", help="a preset or shipped model (default: the stream's model)")
    p.add_argument("--layers", default=None, help="1, 2, ... or 'all' (default: the tier's stream setting)")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--sizes", nargs="+", default=["370x463", "480x640", "1088x1376"])
    p.add_argument("--rounds", type=int, default=5)
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    print(f"tier {a.tier}, {a.threads} threads, layers {a.layers or 'the tier setting'}; seconds")
    print("size        step min  step med  cold min  cold med  step/cold (min)")
    for size in a.sizes:
        h, w = map(int, size.split("x"))
        y, rgb, gt = make_inputs(h, w, 1)
        model = named_model(a.tier)
        settings = None if a.layers is None else {"layers": None if a.layers == "all" else int(a.layers)}
        stream = StreamRestorer(model, settings)
        g = torch.Generator().manual_seed(1)

        def frame() -> torch.Tensor:
            return torch.where(y > 0, (gt + 5 * torch.randn(y.shape, generator=g)).clamp_min(1.0), torch.zeros_like(y))

        steps, colds = [], []
        with torch.no_grad():
            for _ in range(10):  # the cold first frame and 9 steps: every static run has its full mean (max_frames 8)
                stream.step(frame(), rgb)
            model(frame(), rgb)
            for _ in range(a.rounds):
                f = frame()
                t0 = time.perf_counter()
                stream.step(f, rgb)
                steps.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                model(f, rgb)
                colds.append(time.perf_counter() - t0)
        print(f"{h}x{w:<6d} {min(steps):8.3f}  {statistics.median(steps):8.3f}  {min(colds):8.3f}  "
              f"{statistics.median(colds):8.3f}  {min(steps) / min(colds):6.2f}", flush=True)


if __name__ == "__main__":
    main()
