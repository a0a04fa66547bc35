"""Issue 28: the RMSE of every frame of a static stream of a Middlebury 2006 scene (the FITTING split), new
degradation every frame, for the shipped stream (every layer) and ``StreamConfig.layers = 1``, next to
frame-by-frame restoration; the ``fast`` tier.

    python docs/measurements/issue28-stream/stream_2006_frames.py [--frames 10] [--scenes Baby1 Cloth1 Midd1 Wood1]

Shows how the stream's error moves with the age of the static run (static_2006.py gives the means over the last
frames). The held-out 2005/2003/2001 scenes are never loaded here.
"""
from __future__ import annotations

import torch
from middlebury_streams import arguments, degraded_frames, scenes

from torch_depth_sr.evaluation.bench import _metrics
from torch_depth_sr.stream import StreamRestorer, default_stream_model


def main() -> None:
    a = arguments(__doc__, frames=10).parse_args()
    torch.set_num_threads(a.threads)
    model = default_stream_model()  # the stream's model, denoise-fast (the fast tier until the 14th stop)
    for track in ("paper", "sensor"):
        for rec in scenes(track, a.scenes):
            frames = degraded_frames(rec.load(), track, a.frames)
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
