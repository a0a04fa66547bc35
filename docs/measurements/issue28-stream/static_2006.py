"""Issue 28: a stream of a static Middlebury 2006 scene (the FITTING split) with new sensor noise every frame: what
the stream gives with every layer and with ``StreamConfig.layers = 1`` against frame-by-frame restoration.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/static_2006.py [--frames 10] [--scenes Baby1 ...]

Each frame is the ``paper`` or ``sensor`` track's degradation of the scene with seed t (new noise, and for
``sensor`` new holes and flying pixels); the colour does not change, so every pixel is static after the first
frame. Prints the RMSE / MAE against the ground truth over the last half of the frames (the track's metrics, the
mean over the scenes). The held-out 2005/2003/2001 scenes are never loaded here.
"""
from __future__ import annotations

import statistics

import torch
from middlebury_streams import arguments, degraded_frames, scenes

from torch_depth_sr.evaluation.bench import _metrics
from torch_depth_sr.stream import StreamRestorer, default_stream_model


def main() -> None:
    p = arguments(__doc__, frames=10, threads=1)
    p.add_argument("--tracks", nargs="+", default=["paper", "sensor"])
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    model = default_stream_model()  # the stream's model, denoise-fast (the fast tier until the 14th stop)
    for track in a.tracks:
        records = scenes(track, a.scenes)
        scores: dict = {"frame": [], "stream, every layer": [], "stream, layers 1": []}
        for rec in records:
            frames = degraded_frames(rec.load(), track, a.frames)
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
