"""Issue 28: the RMSE of every frame of a static stream of a Middlebury 2006 scene (the FITTING split), new
degradation every frame, for the shipped stream (every layer) and ``StreamConfig.layers = 1``, next to
frame-by-frame restoration; the ``fast`` tier.

    python docs/measurements/issue28-stream/stream_2006_frames.py [--frames 10] [--scenes Baby1 Cloth1 Midd1 Wood1]

Shows how the stream's error moves with the age of the static run (static_2006.py gives the means over the last
frames). The held-out 2005/2003/2001 scenes are never loaded here.
"""
from __future__ import annotations

import argparse

import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr._data_root import data_root
from torch_depth_sr.datasets.discover import find_scenes
from torch_depth_sr.degradations import make_degradation
from torch_depth_sr.evaluation.bench import _metrics
from torch_depth_sr.stream import StreamRestorer


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--frames", type=int, default=10)
    p.add_argument("--scenes", nargs="+", default=["Baby1", "Cloth1", "Midd1", "Wood1"])
    p.add_argument("--threads", type=int, default=2)
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    model = DepthRestorer.from_preset("fast")
    for track in ("paper", "sensor"):
        for rec in [r for r in find_scenes(data_root(), track) if r.name in a.scenes]:
            scene = rec.load()
            frames = []
            for t in range(a.frames):
                s = make_degradation(track, seed=t)(scene)
                s["depth"] = s["depth"].clamp_min(0)
                frames.append(s)
            rows = {"frame": [], "stream, every layer": [], "stream, layers 1": []}
            streams = {"stream, every layer": StreamRestorer(model, {"layers": None}),
                       "stream, layers 1": StreamRestorer(model, {"layers": 1})}
            with torch.no_grad():
                for s in frames:
                    y, rgb = s["depth"][None], s["rgb"][None]
                    rows["frame"].append(_metrics(model(y, rgb), s, track)["rmse"])
                    for k, st in streams.items():
                        rows[k].append(_metrics(st(y, rgb), s, track)["rmse"])
            for k, v in rows.items():
                print(f"{track:6s} {rec.name:7s} {k:20s} " + " ".join(f"{e:.3f}" for e in v), flush=True)


if __name__ == "__main__":
    main()
