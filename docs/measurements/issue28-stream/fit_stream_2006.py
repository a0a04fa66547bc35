"""Issue 28: the stream's ``weight`` and ``max_frames`` on static streams of Middlebury 2006 scenes (the FITTING
split), where the synthetic tuning sequences (``tune_stream.py``) showed no drift but these do
(``stream_2006_frames.txt``: the shipped stream's error rises with the age of the static run).

    python docs/measurements/issue28-stream/fit_stream_2006.py [--frames 16] [--scenes Baby1 Cloth1 Midd1 Wood1]
        [--model default] [--weights 0.5 1 2] [--max-frames 4 8 16]

Each frame is the ``paper`` / ``sensor`` degradation of the scene with seed t; the score of a setting is the mean over
scenes and both tracks of its RMSE over the second half of the frames divided by frame-by-frame restoration's.
Prints one row per setting; writes nothing. The held-out 2005/2003/2001 scenes are never loaded here. ``--model``: a
preset or shipped model instead of the stream's (``denoise-fast``); every other stream setting is the model's own
(its ``config.json``'s ``stream`` group; until the thirty-third stop the other settings were ``StreamConfig()``'s).
"""
from __future__ import annotations

import itertools
import statistics

import torch
from middlebury_streams import arguments, degraded_frames, scenes

from torch_depth_sr.config import StreamConfig
from torch_depth_sr.evaluation.bench import _metrics
from torch_depth_sr.model import named_model
from torch_depth_sr.stream import StreamRestorer, default_stream_model

GRID = {"weight": (0.5, 1.0, 2.0), "max_frames": (4.0, 8.0, 16.0)}


def main() -> None:
    p = arguments(__doc__, frames=16)
    p.add_argument("--model", default=None, help="a preset or shipped model (default: the stream's, denoise-fast)")
    p.add_argument("--weights", type=float, nargs="+", default=list(GRID["weight"]))
    p.add_argument("--max-frames", type=float, nargs="+", default=list(GRID["max_frames"]))
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    # the stream's model, denoise-fast (the fast tier until the 14th stop), or --model
    model = default_stream_model() if a.model is None else named_model(a.model)
    settings = model.config.stream or StreamConfig()
    streams = []  # (track, frames, frame-by-frame rmse over the second half)
    for track in ("paper", "sensor"):
        for rec in scenes(track, a.scenes):
            frames = degraded_frames(rec.load(), track, a.frames)
            with torch.no_grad():
                base = [_metrics(model(s["depth"][None], s["rgb"][None]), s, track)["rmse"]
                        for s in frames[a.frames // 2:]]
            streams.append((track, rec.name, frames, statistics.fmean(base)))
    for w, cap in itertools.product(a.weights, a.max_frames):
        ratios = {}
        for track, name, frames, base in streams:
            st = StreamRestorer(model, settings.replace(weight=w, max_frames=cap))
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
