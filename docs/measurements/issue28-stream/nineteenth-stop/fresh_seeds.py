"""Issue 28: does the stream keep its targets on other scenes of the evaluated recipes? (a check of generalisation;
nothing is fitted here)

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/nineteenth-stop/fresh_seeds.py [--seeds 200 201 ...]

The three recipes of ``STREAM_SEQUENCES`` (the stream track's evaluated sequences: seeds 1–3) and of the tuning
sequences (seeds 101–103), with other seeds (default 200–205): new scenes, movers and sensor noise, nothing else
changed, 30 frames at 120×160 as the track. The stream model (``denoise-fast``) as ``StreamRestorer()`` runs it, and
frame-by-frame restoration with the same model; the stream track's scores (``evaluation.stream.synthetic_metrics``).
Per sequence: RMSE, flicker and trail of the stream divided by frame-by-frame's, and the absolute values; then how
many sequences meet each target of issue 28 (RMSE and trail ≤ 1, flicker ≤ 0.5). The stream track gives the
absolute figures of the same scenes: ``torch-depth-sr bench --track stream --sets synthetic --seeds 200 201 202 203 204
205 --methods frame stream --per-scene``.
"""
from __future__ import annotations

import argparse
import numpy as np
import torch
from tqdm import tqdm

from torch_depth_sr import restore_depth
from torch_depth_sr.datasets.sequences import make_sequence, recipe_sequences
from torch_depth_sr.evaluation.stream import regions, synthetic_metrics
from torch_depth_sr.stream import StreamRestorer, default_stream_model

KEYS = ("rmse", "flicker", "trail")
LIMITS = {"rmse": 1.0, "flicker": 0.5, "trail": 1.0}


def restored_frames(step, seq) -> np.ndarray:
    """Every frame of ``seq`` through ``step(depth, rgb)``, (T,H,W) float32."""
    with torch.no_grad():
        return np.stack([np.asarray(step(seq["depth"][t, 0], torch.from_numpy(seq["rgb"][t])), dtype=np.float32)
                         for t in range(seq["depth"].shape[0])])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--seeds", type=int, nargs="+", default=list(range(200, 206)))
    a = p.parse_args()
    torch.set_num_threads(1)
    model = default_stream_model()
    specs = recipe_sequences(a.seeds)
    rows = []
    for spec in tqdm(specs, desc="sequences"):
        seq = make_sequence(spec, frames=30, height=120, width=160)
        reg = regions(seq)
        base = synthetic_metrics(restored_frames(lambda d, c: restore_depth(d, c, model=model), seq), seq, reg)
        m = synthetic_metrics(restored_frames(StreamRestorer(model).step, seq), seq, reg)
        r = [m[k] / base[k] for k in KEYS]
        rows.append(r)
        tqdm.write(f"{spec.name:22s} " + " ".join(f"{k} {v:.4f}" for k, v in zip(KEYS, r)) + "   stream/frame "
                   + " ".join(f"{k} {m[k]:.2f}/{base[k]:.2f}" for k in KEYS))
    rows = np.array(rows)
    print("mean of the ratios " + " ".join(f"{k} {v:.4f}" for k, v in zip(KEYS, rows.mean(0))))
    for i, k in enumerate(KEYS):
        print(f"{k}: {int((rows[:, i] <= LIMITS[k]).sum())} of {len(rows)} sequences at most {LIMITS[k]} × frame by frame")


if __name__ == "__main__":
    main()
