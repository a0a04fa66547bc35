"""Issue 28: the stream's ``weight`` and ``max_frames`` on static streams of Middlebury 2006 scenes (the FITTING
split), where the synthetic tuning sequences (``tune_stream.py``) showed no drift but these do
(``stream_2006_frames.txt``: the shipped stream's error rises with the age of the static run).

    python docs/measurements/issue28-stream/fit_stream_2006.py [--frames 16] [--scenes Baby1 Cloth1 Midd1 Wood1]

Each frame is the ``paper`` / ``sensor`` degradation of the scene with seed t; the score of a setting is the mean over
scenes and both tracks of its RMSE over the second half of the frames divided by frame-by-frame restoration's.
Prints one row per setting; writes nothing. The held-out 2005/2003/2001 scenes are never loaded here.
"""
from __future__ import annotations

import itertools
import statistics

import torch
from middlebury_streams import arguments, degraded_frames, scenes

from torch_depth_sr.config import StreamConfig
from torch_depth_sr.evaluation.bench import _metrics
from torch_depth_sr.stream import StreamRestorer, default_stream_model

GRID = {"weight": (0.5, 1.0, 2.0), "max_frames": (4.0, 8.0, 16.0)}


def main() -> None:
    a = arguments(__doc__, frames=16).parse_args()
    torch.set_num_threads(a.threads)
    model = default_stream_model()  # the stream's model, denoise-fast (the fast tier until the 14th stop)
    streams = []  # (track, frames, frame-by-frame rmse over the second half)
    for track in ("paper", "sensor"):
        for rec in scenes(track, a.scenes):
            frames = degraded_frames(rec.load(), track, a.frames)
            with torch.no_grad():
                base = [_metrics(model(s["depth"][None], s["rgb"][None]), s, track)["rmse"]
                        for s in frames[a.frames // 2:]]
            streams.append((track, rec.name, frames, statistics.fmean(base)))
    for w, cap in itertools.product(GRID["weight"], GRID["max_frames"]):
        ratios = {}
        for track, name, frames, base in streams:
            st = StreamRestorer(model, StreamConfig(weight=w, max_frames=cap))
            errs = []
            with torch.no_grad():
                for t, s in enumerate(frames):
                    out = st(s["depth"][None], s["rgb"][None])
                    if t >= a.frames // 2:
                        errs.append(_metrics(out, s, track)["rmse"])
            ratios[(track, name)] = statistics.fmean(errs) / base
        worst = max(ratios, key=ratios.get)
        print(f"weight {w:g} max_frames {cap:g}: rmse / frame-by-frame mean {statistics.fmean(ratios.values()):.4f}, "
              f"worst {ratios[worst]:.4f} ({worst[0]} {worst[1]})", flush=True)


if __name__ == "__main__":
    main()
