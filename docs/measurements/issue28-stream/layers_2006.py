"""Issue 28: ``StreamConfig.layers`` on streams of Middlebury 2006 scenes (the FITTING split): the stream with every
layer against ``layers = 1`` (one layer where a static run has its full mean, every layer on crops elsewhere), on a
static stream and on one where a near square enters at frame 10 and moves 4 px per frame; the ``fast`` tier, the
stream settings of the library.

    python docs/measurements/issue28-stream/layers_2006.py [--frames 16] [--scenes Baby1 Cloth1 Midd1 Wood1]

Each frame is the ``paper`` / ``sensor`` degradation with seed t. Prints per scene the RMSE over the frames from
``--frames // 2`` (static) or from frame 10 (mover) divided by frame-by-frame restoration's, then the mean and the
worst. The held-out 2005/2003/2001 scenes are never loaded here.
"""
from __future__ import annotations

import argparse
import statistics

import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr._data_root import data_root
from torch_depth_sr.datasets.discover import find_scenes
from torch_depth_sr.degradations import make_degradation
from torch_depth_sr.evaluation.bench import _metrics
from torch_depth_sr.stream import StreamRestorer


def frames_of(scene: dict, track: str, count: int, mover: bool) -> list:
    h, w = scene["gt"].shape[-2:]
    size = min(h, w) // 5
    out = []
    for t in range(count):
        s = {k: (v.clone() if torch.is_tensor(v) else v) for k, v in scene.items()}
        if mover and t >= 10:
            r0, c0 = h // 3, w // 4 + 4 * (t - 10)
            s["gt"][..., r0:r0 + size, c0:c0 + size] = s["gt"].max() * 1.1
            s["rgb"][..., r0:r0 + size, c0:c0 + size] = torch.tensor([0.1, 0.8, 0.2]).view(3, 1, 1)
        d = make_degradation(track, seed=t)(s)
        d["depth"] = d["depth"].clamp_min(0)
        out.append(d)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--frames", type=int, default=16)
    p.add_argument("--scenes", nargs="+", default=["Baby1", "Cloth1", "Midd1", "Wood1"])
    p.add_argument("--threads", type=int, default=2)
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    model = DepthRestorer.from_preset("fast")
    for case, mover, start in (("static", False, a.frames // 2), ("mover", True, 10)):
        for track in ("paper", "sensor"):
            ratios: dict = {"every layer": [], "layers 1": []}
            for rec in [r for r in find_scenes(data_root(), track) if r.name in a.scenes]:
                frames = frames_of(rec.load(), track, a.frames, mover)
                with torch.no_grad():
                    base = statistics.fmean(_metrics(model(s["depth"][None], s["rgb"][None]), s, track)["rmse"]
                                            for s in frames[start:])
                cells = []
                for name, layers in (("every layer", None), ("layers 1", 1)):
                    stream = StreamRestorer(model, {"layers": layers})
                    errs = []
                    with torch.no_grad():
                        for t, s in enumerate(frames):
                            out = stream(s["depth"][None], s["rgb"][None])
                            if t >= start:
                                errs.append(_metrics(out, s, track)["rmse"])
                    ratios[name].append(statistics.fmean(errs) / base)
                    cells.append(f"{name} {ratios[name][-1]:.4f}")
                print(f"{case:6s} {track:6s} {rec.name:7s} " + ", ".join(cells), flush=True)
            print(f"{case:6s} {track:6s} mean / worst: " + ", ".join(
                f"{k} {statistics.fmean(v):.4f} / {max(v):.4f}" for k, v in ratios.items()), flush=True)


if __name__ == "__main__":
    main()
