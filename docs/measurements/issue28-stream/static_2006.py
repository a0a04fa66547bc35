"""Issue 28: a stream of a static Middlebury 2006 scene (the FITTING split) with new sensor noise every frame: what
the stream gives with every layer and with ``StreamConfig.layers = 1`` against frame-by-frame restoration.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/static_2006.py [--frames 10] [--scenes Baby1 ...]

Each frame is the ``paper`` or ``sensor`` track's degradation of the scene with seed t (new noise, and for
``sensor`` new holes and flying pixels); the colour does not change, so every pixel is static after the first
frame. Prints the RMSE / MAE against the ground truth over the last half of the frames (the track's metrics, the
mean over the scenes). The held-out 2005/2003/2001 scenes are never loaded here.
"""
from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "issue27-tiers"))

from torch_depth_sr import DepthRestorer  # noqa: E402
from torch_depth_sr._data_root import data_root  # noqa: E402
from torch_depth_sr.datasets.discover import find_scenes  # noqa: E402
from torch_depth_sr.degradations import make_degradation  # noqa: E402
from torch_depth_sr.evaluation.bench import _metrics  # noqa: E402
from torch_depth_sr.stream import StreamRestorer  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--frames", type=int, default=10)
    p.add_argument("--scenes", nargs="+", default=["Baby1", "Cloth1", "Midd1", "Wood1"])
    p.add_argument("--tracks", nargs="+", default=["paper", "sensor"])
    a = p.parse_args()
    torch.set_num_threads(1)
    model = DepthRestorer.from_preset("fast")
    for track in a.tracks:
        records = [r for r in find_scenes(data_root(), track) if r.name in a.scenes]
        scores: dict = {"frame": [], "stream, every layer": [], "stream, layers 1": []}
        for rec in records:
            scene = rec.load()
            frames = []
            for t in range(a.frames):
                s = make_degradation(track, seed=t)(scene)
                s["depth"] = s["depth"].clamp_min(0)
                frames.append(s)
            streams = {"stream, every layer": StreamRestorer(model, {"layers": None}),
                       "stream, layers 1": StreamRestorer(model, {"layers": 1})}
            rows: dict = {k: [] for k in scores}
            for t, s in enumerate(frames):
                y, rgb = s["depth"][None], s["rgb"][None]
                with torch.no_grad():
                    outs = {"frame": model(y, rgb), **{k: st(y, rgb) for k, st in streams.items()}}
                if t >= a.frames // 2:
                    for k, out in outs.items():
                        m = _metrics(out, s, track)
                        rows[k].append((m["rmse"], m["mae"]))
            for k in scores:
                scores[k].append((statistics.fmean(r for r, _ in rows[k]), statistics.fmean(e for _, e in rows[k])))
            print(f"{track} {rec.name}: " + ", ".join(f"{k} {statistics.fmean(r for r, _ in rows[k]):.3f}"
                                                        for k in scores), flush=True)
        print(f"{track}, mean over {len(records)} scenes, frames {a.frames // 2}-{a.frames - 1}: " + "; ".join(
            f"{k} {statistics.fmean(r for r, _ in v):.4f} / {statistics.fmean(e for _, e in v):.4f}"
            for k, v in scores.items()), flush=True)


if __name__ == "__main__":
    main()
