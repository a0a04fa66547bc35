"""Issue 28: a stream setting on and off (default ``keep_scale``) on the TUNING sequences only
(``datasets.sequences.TUNING_SEQUENCES``; the evaluated sequences and the real recordings are never loaded here).

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/setting_tuning.py [--setting keep_scale] [--frames 30]

The stream model (``denoise-fast``). Per tuning sequence: RMSE, flicker and trail of the stream with the setting off
and on, each divided by frame-by-frame restoration's (the stream track's scores, ``evaluation.stream``), then the mean.
"""
from __future__ import annotations

import argparse

import numpy as np
import torch

from torch_depth_sr import restore_depth
from torch_depth_sr.datasets.sequences import TUNING_SEQUENCES, make_sequence
from torch_depth_sr.evaluation.stream import regions, synthetic_metrics
from torch_depth_sr.stream import StreamRestorer, default_stream_model


def _outputs(step, seq) -> np.ndarray:
    with torch.no_grad():
        return np.stack([np.asarray(step(seq["depth"][t, 0], torch.from_numpy(seq["rgb"][t])), dtype=np.float32)
                         for t in range(seq["depth"].shape[0])])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--setting", default="keep_scale", help="a boolean field of StreamConfig")
    p.add_argument("--frames", type=int, default=30)
    a = p.parse_args()
    model = default_stream_model()
    keys = ("rmse", "flicker", "trail")
    ratios: dict = {"off": [], "on": []}
    for spec in TUNING_SEQUENCES:
        seq = make_sequence(spec, frames=a.frames, height=120, width=160)
        reg = regions(seq)
        base = synthetic_metrics(_outputs(lambda d, c: restore_depth(d, c, model=model), seq), seq, reg)
        cells = []
        for name, value in (("off", False), ("on", True)):
            m = synthetic_metrics(_outputs(StreamRestorer(model, {a.setting: value}).step, seq), seq, reg)
            r = [m[k] / base[k] for k in keys]
            ratios[name].append(r)
            cells.append(f"{name}: " + " ".join(f"{k} {v:.4f}" for k, v in zip(keys, r)))
        print(f"{spec.name:22s} " + " | ".join(cells), flush=True)
    for name, rows in ratios.items():
        print(f"mean {name}: " + " ".join(f"{k} {v:.4f}" for k, v in zip(keys, np.nanmean(np.array(rows), 0))))


if __name__ == "__main__":
    main()
