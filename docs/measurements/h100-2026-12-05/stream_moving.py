"""A stream step against a cold frame of the same model on *moving* content, on any device: the speed track's
``stream-fast`` rows time a static scene (the stream's best case), this times the evaluated synthetic sequences,
whose movers and camera pan make the stream run its later layers on crops and re-match.

    python docs/measurements/h100-2026-12-05/stream_moving.py --device cuda --size 480x640 --batch 1 --frames 12

B streams at once (``--batch``): the first B of the stream track's evaluated sequences, then its tuning ones. Each
frame is a timed stream step then a timed cold frame of the stream's model (``restore_depth(..., model=)``) on the
same input, each after a device synchronisation; the table gives the medians over frames ``--skip`` and later, and
the median of the per-frame ratios.
"""
import argparse
import json
import statistics
import time

import numpy as np
import torch

from torch_depth_sr import restore_depth
from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, TUNING_SEQUENCES, make_sequence
from torch_depth_sr.stream import StreamRestorer, default_stream_model


def sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--size", default="480x640")
    p.add_argument("--batch", type=int, default=1)
    p.add_argument("--frames", type=int, default=12)
    p.add_argument("--skip", type=int, default=3, help="frames not counted (the first is the stream's cold one)")
    p.add_argument("--settings", default=None, help="StreamConfig changes as JSON, e.g. '{\"hold\": null}'")
    p.add_argument("--json", default=None)
    a = p.parse_args()
    h, w = (int(t) for t in a.size.split("x"))
    specs = (list(STREAM_SEQUENCES) + list(TUNING_SEQUENCES))[:a.batch]
    seqs = [make_sequence(s, frames=a.frames, height=h, width=w) for s in specs]
    depth = torch.from_numpy(np.stack([s["depth"].astype(np.float32) for s in seqs], 1)).to(a.device)  # (T,B,1,H,W)
    rgb = torch.from_numpy(np.stack([s["rgb"] for s in seqs], 1)).to(a.device)
    model = default_stream_model().to(a.device).eval()
    stream = StreamRestorer(model, json.loads(a.settings) if a.settings else None)
    steps, colds = [], []
    with torch.no_grad():
        restore_depth(depth[0], rgb[0], model=model)  # warm-up of the cold path (first CUDA kernels, caches)
        for t in range(a.frames):
            sync(a.device)
            t0 = time.perf_counter()
            stream.step(depth[t], rgb[t])
            sync(a.device)
            t1 = time.perf_counter()
            restore_depth(depth[t], rgb[t], model=model)
            sync(a.device)
            t2 = time.perf_counter()
            steps.append(t1 - t0)
            colds.append(t2 - t1)
    kept = range(a.skip, a.frames)
    row = {"device": a.device, "settings": a.settings, "gpu": torch.cuda.get_device_name() if a.device.startswith("cuda") else None,
           "size": a.size, "batch": a.batch, "sequences": [s.name for s in specs], "frames": a.frames,
           "step_ms": 1e3 * statistics.median(steps[i] for i in kept) / a.batch,
           "cold_ms": 1e3 * statistics.median(colds[i] for i in kept) / a.batch,
           "ratio": statistics.median(steps[i] / colds[i] for i in kept),
           "first_frame_ms": 1e3 * steps[0] / a.batch, "steps_s": steps, "colds_s": colds}
    print(f"| {a.device} | {a.size} | {a.batch} | {row['step_ms']:.1f} | {row['cold_ms']:.1f} | {row['ratio']:.2f} |",
          flush=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(row, f, indent=1)


if __name__ == "__main__":
    main()
