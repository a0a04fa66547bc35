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

import statistics

import torch
from middlebury_streams import MOVER_FROM, arguments, degraded_frames, scenes

from torch_depth_sr.evaluation.bench import _metrics
from torch_depth_sr.stream import StreamRestorer, default_stream_model


def main() -> None:
    a = arguments(__doc__, frames=16).parse_args()
    torch.set_num_threads(a.threads)
    model = default_stream_model()  # the stream's model, denoise-fast (the fast tier until the 14th stop)
    for case, mover, start in (("static", False, a.frames // 2), ("mover", True, MOVER_FROM)):
        for track in ("paper", "sensor"):
            ratios: dict = {"every layer": [], "layers 1": []}
            for rec in scenes(track, a.scenes):
                frames = degraded_frames(rec.load(), track, a.frames, mover)
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
