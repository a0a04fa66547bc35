"""Issue 28: a stream setting on and off (default ``keep_scale``: the previous frame's scale policy while the scene
stays) on streams of Middlebury 2006 scenes (the FITTING split): the stream model (``denoise-fast``; ``--model``:
another) with each, against frame-by-frame restoration, on a static stream and on one with a mover.

    python docs/measurements/issue28-stream/setting_2006.py [--setting keep_scale] [--off false --on true] [--frames 16]
        [--scenes Baby1 Cloth1 Midd1 Wood1] [--model default]

Each frame is the ``paper`` / ``sensor`` degradation with seed t. Prints per scene the RMSE over the frames from
``--frames // 2`` (static) or from frame 10 (mover) divided by frame-by-frame restoration's, then the mean and the
worst, and the largest difference between the two streams' outputs. The held-out scenes are never loaded here.
"""
from __future__ import annotations

import json
import statistics

import torch
from middlebury_streams import MOVER_FROM, arguments, degraded_frames, scenes

from torch_depth_sr.evaluation.bench import _metrics
from torch_depth_sr.model import named_model
from torch_depth_sr.stream import StreamRestorer, default_stream_model


def main() -> None:
    p = arguments(__doc__, frames=16)
    p.add_argument("--setting", default="keep_scale", help="a field of StreamConfig")
    p.add_argument("--off", default="false", help="its value for 'off', as JSON (default false; e.g. null)")
    p.add_argument("--on", default="true", help="its value for 'on', as JSON (default true; e.g. 80)")
    p.add_argument("--model", default=None, help="a preset or shipped model (default: the stream's, denoise-fast)")
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    model = default_stream_model() if a.model is None else named_model(a.model)
    variants = {"off": {a.setting: json.loads(a.off)}, "on": {a.setting: json.loads(a.on)}}
    for case, mover, start in (("static", False, a.frames // 2), ("mover", True, MOVER_FROM)):
        for track in ("paper", "sensor"):
            ratios: dict = {k: [] for k in variants}
            for rec in scenes(track, a.scenes):
                frames = degraded_frames(rec.load(), track, a.frames, mover)
                streams = {k: StreamRestorer(model, v) for k, v in variants.items()}
                err: dict = {k: [] for k in ("frame", *variants)}
                gap = 0.0
                with torch.no_grad():
                    for t, s in enumerate(frames):
                        depth, rgb = s["depth"][None], s["rgb"][None]
                        outs = {k: st(depth, rgb) for k, st in streams.items()}
                        if t < start:
                            continue
                        err["frame"].append(_metrics(model(depth, rgb), s, track)["rmse"])
                        for k, o in outs.items():
                            err[k].append(_metrics(o, s, track)["rmse"])
                        gap = max(gap, float((outs["on"] - outs["off"]).abs().max()))
                base = statistics.fmean(err["frame"])
                for k in variants:
                    ratios[k].append(statistics.fmean(err[k]) / base)
                line = ", ".join(f"{k} {ratios[k][-1]:.4f}" for k in variants)
                print(f"{case:6s} {track:6s} {rec.name:7s} {line}, largest difference {gap:.4f}", flush=True)
            print(f"{case:6s} {track:6s} mean / worst: " + ", ".join(
                f"{k} {statistics.fmean(v):.4f} / {max(v):.4f}" for k, v in ratios.items()), flush=True)


if __name__ == "__main__":
    main()
