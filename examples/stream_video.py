"""Restore a depth video with StreamRestorer, against restoring each frame alone (synthetic; no files needed).

    python examples/stream_video.py [--sequence pan-then-hold] [--frames 30] [--png stream_video.png]

One of the stream track's sequences (a camera that pans then holds, movers, a stereo-like sensor with noise, holes
and flying pixels; ground truth in mm). Prints each method's RMSE, its flicker (the temporal std of the error where
the scene stays still) and its trail error (near the movers), the stream track's scores, and writes a PNG of the last
frame: raw, frame by frame, the stream and their error maps.
"""
from __future__ import annotations

import argparse

import cv2
import numpy as np
import torch
from tqdm import tqdm

from torch_depth_sr import StreamRestorer, restore_depth
from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, make_sequence
from torch_depth_sr.evaluation.stream import synthetic_metrics
from torch_depth_sr.stream import default_stream_model


def main(sequence: str = "pan-then-hold", frames: int = 30, png: str | None = "stream_video.png") -> dict:
    spec = next(s for s in STREAM_SEQUENCES if s.name == sequence)
    seq = make_sequence(spec, frames=frames)
    model = default_stream_model()  # denoise-fast: the model the stream's settings were fitted for
    stream = StreamRestorer(model)
    alone, streamed = [], []
    with torch.no_grad():
        for depth, rgb in tqdm(zip(seq["depth"][:, 0], seq["rgb"]), total=frames, desc=sequence):
            alone.append(restore_depth(depth, rgb, model=model))  # uint16 mm in, uint16 mm out
            streamed.append(stream.step(depth, rgb))  # the same, with the previous frames' help
    scores = {name: synthetic_metrics(np.stack(out).astype(np.float32), seq)
              for name, out in (("frame by frame", alone), ("stream", streamed))}
    print(f"{sequence}, {frames} frames of {seq['depth'].shape[-1]}×{seq['depth'].shape[-2]}, depth in mm")
    for name, m in scores.items():
        print(f"  {name:15s} RMSE {m['rmse']:7.2f}   flicker {m['flicker']:6.2f}   trail {m['trail']:7.2f}")
    if png:
        gt = seq["gt"][-1, 0]
        tiles = [seq["depth"][-1, 0], alone[-1], streamed[-1]]
        depth_row = [_colour(t.astype(np.float32), gt) for t in tiles]
        error_row = [_error(t.astype(np.float32), gt) for t in tiles]
        grid = np.vstack([np.hstack(depth_row), np.hstack(error_row)])
        cv2.imwrite(png, cv2.resize(grid, None, fx=2, fy=2, interpolation=cv2.INTER_NEAREST))
        print(f"wrote {png}: raw, frame by frame, stream (top); |error| 0-50 mm (bottom)")
    return scores


def _colour(depth: np.ndarray, gt: np.ndarray) -> np.ndarray:
    lo, hi = float(gt.min()), float(gt.max())
    v = np.clip((depth - lo) / max(hi - lo, 1e-6), 0, 1)
    img = cv2.applyColorMap((255 * v).astype(np.uint8), cv2.COLORMAP_TURBO)
    img[depth <= 0] = 0  # holes black
    return img


def _error(depth: np.ndarray, gt: np.ndarray) -> np.ndarray:
    e = np.clip(np.abs(np.where(depth > 0, depth, 0) - gt) / 50.0, 0, 1)
    return cv2.applyColorMap((255 * e).astype(np.uint8), cv2.COLORMAP_INFERNO)


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sequence", default="pan-then-hold", choices=[s.name for s in STREAM_SEQUENCES])
    p.add_argument("--frames", type=int, default=30)
    p.add_argument("--png", default="stream_video.png", help="the picture to write ('' for none)")
    a = p.parse_args()
    main(a.sequence, a.frames, a.png or None)
