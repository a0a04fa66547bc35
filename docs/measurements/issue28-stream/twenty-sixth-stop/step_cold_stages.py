"""Issue 28, twenty-sixth stop: a stream step and a cold frame of the same model on the same moving frames, stage by
stage (the model's own stage timings, ``timings=True``): where a step on moving sensor input is cheaper than a cold
frame and where it is not. Frames 10-19 of an evaluated sequence at 480×640, medians in ms.

    OMP_NUM_THREADS=2 python docs/measurements/issue28-stream/twenty-sixth-stop/step_cold_stages.py [static-2movers]

``SETTINGS`` (JSON, optional) gives the stream's settings, e.g. ``SETTINGS='{"hold": 0.5}'`` (the twenty-eighth stop).

``total`` minus the named stages is the rest (the observation, the change test, the fill, the state).
"""
import collections
import json
import os
import statistics
import sys
import time

import numpy as np
import torch

from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, make_sequence
from torch_depth_sr.stream import StreamRestorer, default_stream_model


def main() -> None:
    name = sys.argv[1] if len(sys.argv) > 1 else "static-2movers"
    seq = make_sequence(next(s for s in STREAM_SEQUENCES if s.name == name), frames=20, height=480, width=640)
    model = default_stream_model().eval()
    stream = StreamRestorer(model, json.loads(os.environ.get("SETTINGS", "{}")))
    step, cold = collections.defaultdict(list), collections.defaultdict(list)
    with torch.no_grad():
        for t in range(20):
            d, rgb = seq["depth"][t].astype(np.float32), seq["rgb"][t]
            t0 = time.perf_counter()
            r = stream.step(d, rgb, return_details=True, timings=True)
            t1 = time.perf_counter()
            if t < 10:
                continue
            c = model.restore_with_details(torch.from_numpy(d)[None], torch.from_numpy(rgb)[None], timings=True)
            t2 = time.perf_counter()
            step["total"].append(t1 - t0)
            cold["total"].append(t2 - t1)
            for k, v in r.info["seconds"].items():
                step[k].append(v)
            for k, v in c.info["seconds"].items():
                cold[k].append(v)
    print(f"{name} 480x640, frames 10-19, {torch.get_num_threads()} threads; medians in ms")
    for k in sorted(set(step) | set(cold)):
        s = 1e3 * statistics.median(step[k]) if step[k] else float("nan")
        c = 1e3 * statistics.median(cold[k]) if cold[k] else float("nan")
        print(f"{k:24s} step {s:7.1f}  cold {c:7.1f}")


if __name__ == "__main__":
    main()
