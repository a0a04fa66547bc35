"""Issue 28: where the stream's flicker sits on the synthetic TUNING sequences (never the evaluated ones): for each,
the flicker of the stream and of frame-by-frame restoration (the ``fast`` tier), the share of the stream's flicker
carried by the 5 % of still pixels that flicker most, and how many of those lie at a depth edge (ground-truth
gradient above 20 mm/px) against all still pixels.

    OMP_NUM_THREADS=2 python docs/measurements/issue28-stream/flicker_sources.py

Prints a line per sequence; writes nothing. ``flicker_sources.txt`` holds the run before and after the sixth stop's
held-out departures (``StreamRestorer`` keeps a first departure from a static run out of its mean).
"""
from __future__ import annotations

import numpy as np
import torch

from torch_depth_sr import restore_depth
from torch_depth_sr.datasets.sequences import TUNING_SEQUENCES, make_sequence
from torch_depth_sr.evaluation.stream import regions
from torch_depth_sr.stream import StreamRestorer, default_stream_model


def main() -> None:
    model = default_stream_model()  # the stream's model, denoise-fast (the fast tier until the 14th stop)
    for spec in TUNING_SEQUENCES:
        seq = make_sequence(spec, frames=30, height=120, width=160)
        reg = regions(seq)
        stream, outs, frame = StreamRestorer(model), [], []
        for t in range(seq["depth"].shape[0]):
            d, rgb = seq["depth"][t, 0], torch.from_numpy(seq["rgb"][t])[None]
            with torch.no_grad():
                outs.append(np.asarray(stream.step(d, rgb), np.float64))
                frame.append(np.asarray(restore_depth(d, rgb, model=model), np.float64))
        gt = seq["gt"][:, 0].astype(np.float64)
        t0, still = reg["frames"], reg["static"]

        def flicker(o):
            return (np.stack(o)[t0][:, still] - gt[t0][:, still]).std(0)

        fs, ff = flicker(outs), flicker(frame)
        top = np.argsort(-fs)[:max(1, fs.size // 20)]
        gy, gx = np.gradient(gt[t0][0])
        edge = (np.hypot(gy, gx) > 20)[still]
        print(f"{spec.name:22s} flicker stream {fs.mean():.2f} frame {ff.mean():.2f} ({fs.mean() / ff.mean():.3f}); "
              f"top 5 % of still px carry {fs[top].sum() / fs.sum():.2f} of it; at a depth edge {edge[top].mean():.2f} "
              f"of them, {edge.mean():.2f} of all still px", flush=True)


if __name__ == "__main__":
    torch.set_num_threads(2)
    main()
