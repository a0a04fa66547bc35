"""Inference time of one full frame, scalar (`from_pretrained("denoise")`) vs a guided model folder, alternated.

    OMP_NUM_THREADS=1 PYTHONPATH=. python docs/measurements/guidance/frame_time.py runs/guided/best --scene Art

Both models run on the same `paper`-track input, alternately, `--repeats` times each (1 thread); prints the
median seconds of each as JSON. Alternating keeps a shared machine's load the same for both.
"""
from __future__ import annotations

import argparse
import json
import statistics
import time

import torch

from torch_depth_sr import DepthRestorer


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("model")
    p.add_argument("--scene", default="Art")
    p.add_argument("--repeats", type=int, default=3)
    a = p.parse_args()
    torch.set_num_threads(1)
    from torch_depth_sr._data_root import data_root
    from torch_depth_sr.evaluation.bench import _samples

    (rec, sample), = list(_samples("paper", data_root(), [a.scene], None))
    y, rgb = sample["depth"][None], sample["rgb"][None]
    models = {"scalar (denoise)": DepthRestorer.from_pretrained("denoise"), a.model: DepthRestorer.load(a.model)}
    times: dict = {k: [] for k in models}
    with torch.no_grad():
        for m in models.values():
            m(y, rgb)  # warm-up
        for _ in range(a.repeats):
            for k, m in models.items():
                t0 = time.perf_counter()
                m(y, rgb)
                times[k].append(time.perf_counter() - t0)
    print(json.dumps({"scene": rec.name, "size": list(y.shape[-2:]),
                      "median_seconds": {k: round(statistics.median(v), 3) for k, v in times.items()},
                      "seconds": {k: [round(t, 3) for t in v] for k, v in times.items()}}))


if __name__ == "__main__":
    main()
