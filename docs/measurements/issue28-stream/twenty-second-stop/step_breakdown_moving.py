"""Where a stream step goes on moving sensor input: each stage of ``DepthRestorer._run`` and of the stream's hooks
timed with a wrapper (wall clock, so the numba kernels' threads count once), summed over steps 10–19 of one of the
stream track's evaluated sequences, next to cold frames of the same model on the same frames. Also the share of
pixels held (item 9 of docs/stream.md), fresh (the later layers run there) and the later layers' crop coverage.

    OMP_NUM_THREADS=2 python docs/measurements/issue28-stream/twenty-second-stop/step_breakdown_moving.py \
        --sequence static-2movers --size 480x640

The observation and post-step rows count both the stream's steps and the cold frames (``n``); ``stream.post`` is the stream's alone.
"""
import argparse
import collections
import statistics
import time

import numpy as np
import torch

import torch_depth_sr.model as model_module
import torch_depth_sr.post_steps as post_steps
import torch_depth_sr.stream.crop_layers as crop_layers
import torch_depth_sr.stream.frame as frame
from torch_depth_sr import restore_depth
from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, make_sequence
from torch_depth_sr.stream import StreamRestorer, default_stream_model
from torch_depth_sr.stream.matching import crops

TIMES = collections.defaultdict(list)
COVER: list = []


def timed(owner, name: str, label: str) -> None:
    f = getattr(owner, name)

    def wrapper(*a, **k):
        t0 = time.perf_counter()
        r = f(*a, **k)
        TIMES[label].append(time.perf_counter() - t0)
        return r

    setattr(owner, name, wrapper)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sequence", default="static-2movers", choices=[s.name for s in STREAM_SEQUENCES])
    p.add_argument("--size", default="480x640")
    a = p.parse_args()
    h, w = (int(t) for t in a.size.split("x"))
    timed(model_module, "observe", "observation (step and cold)")
    for n in ["observe", "initial", "run_layers", "post", "keep"]:
        timed(frame.StreamFrame, n, "stream." + n)
    for n in ["change_test", "join_runs", "grow_runs", "remembered_spread"]:
        timed(frame, n, "· " + n)
    later = frame.run_later_layers

    def later_layers(layers, state, obs, changed):
        boxes = crops(changed, crop_layers.padding(obs, len(layers)))
        area = sum((r.stop - r.start) * (c.stop - c.start) for r, c, _, _ in boxes)
        COVER.append((float(changed.float().mean()), area / changed.shape[-1] / changed.shape[-2]))
        t0 = time.perf_counter()
        out = later(layers, state, obs, changed)
        TIMES["· later layers (crops)"].append(time.perf_counter() - t0)
        return out

    frame.run_later_layers = later_layers
    for cls in [post_steps.EdgeSnapStep, post_steps.EdgeRefitStep, post_steps.DenoiseRefineStep,
                post_steps.FidelityBandStep]:
        timed(cls, "forward", cls.__name__ + " (step and cold)")
    spec = next(s for s in STREAM_SEQUENCES if s.name == a.sequence)
    seq = make_sequence(spec, frames=20, height=h, width=w)
    model = default_stream_model().eval()
    stream = StreamRestorer(model)
    steps, colds, held = [], [], []
    with torch.no_grad():
        restore_depth(seq["depth"][0].astype(np.float32), seq["rgb"][0], model=model)
        for t in range(20):
            if t == 10:
                TIMES.clear()
                COVER.clear()
            depth, rgb = seq["depth"][t].astype(np.float32), seq["rgb"][t]
            t0 = time.perf_counter()
            out = stream.step(depth, rgb, return_details=True)
            t1 = time.perf_counter()
            if t >= 10:
                restore_depth(depth, rgb, model=model)
                colds.append(time.perf_counter() - t1)
                steps.append(t1 - t0)
                held.append(out.info["stream"].get("held", 0.0))
    print(f"{a.sequence} {a.size}, steps 10-19, {torch.get_num_threads()} threads")
    print(f"step median {1e3 * statistics.median(steps):.1f} ms, cold frame median {1e3 * statistics.median(colds):.1f} ms")
    print(f"held {100 * min(held):.0f}-{100 * max(held):.0f} %, fresh {100 * min(c[0] for c in COVER):.1f}-"
          f"{100 * max(c[0] for c in COVER):.1f} %, later layers' crops cover {100 * min(c[1] for c in COVER):.0f}-"
          f"{100 * max(c[1] for c in COVER):.0f} % of the frame")
    for k, v in TIMES.items():
        print(f"{k:40s} {1e3 * sum(v) / len(steps):7.1f} ms per step  (n={len(v)})")


if __name__ == "__main__":
    main()
