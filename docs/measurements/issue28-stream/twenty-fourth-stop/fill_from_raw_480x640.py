"""Issue 28, twenty-fourth stop: the twenty-second stop's x⁰ fill variants (``tried_fill_from_raw.py``: the fill fed
the readings the stream holds out or drops) at 480×640 on the three tuning sequences, where ``tune-pan-then-hold``'s
excess lies in the holes' fill (``rmse_excess.py``). Nothing in the package changes: the variants are that script's
patches, run here at another size.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-fourth-stop/fill_from_raw_480x640.py

Per scene each variant's RMSE, flicker and trail divided by frame-by-frame restoration's, then the means.
"""
from __future__ import annotations

import sys
from multiprocessing import Pool
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "twenty-second-stop"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "nineteenth-stop"))
from fresh_seeds import KEYS, restored_frames  # noqa: E402
from tried_fill_from_raw import patch  # noqa: E402  (the twenty-second stop's variants)

from torch_depth_sr import restore_depth  # noqa: E402
from torch_depth_sr.datasets.sequences import TUNING_SEQUENCES, make_sequence  # noqa: E402
from torch_depth_sr.evaluation.stream import regions, synthetic_metrics  # noqa: E402
from torch_depth_sr.stream import StreamRestorer, default_stream_model  # noqa: E402

VARIANTS = ("shipped", "departures@holes", "outliers@sensor-holes", "outliers+departures@sensor-holes")


def scene(spec) -> tuple[str, list]:
    torch.set_num_threads(1)
    model = default_stream_model()
    seq = make_sequence(spec, frames=30, height=480, width=640)
    reg = regions(seq)
    patch("shipped")
    base = synthetic_metrics(restored_frames(lambda d, c: restore_depth(d, c, model=model), seq), seq, reg)
    rows = []
    for v in VARIANTS:
        patch(v)
        m = synthetic_metrics(restored_frames(StreamRestorer(model).step, seq), seq, reg)
        rows.append([m[k] / base[k] for k in KEYS])
    patch("shipped")
    return spec.name, rows


def main() -> None:
    with Pool(2) as pool:
        res = pool.map(scene, list(TUNING_SEQUENCES), chunksize=1)
    print("tuning at 480x640, 30 frames; rmse flicker trail, stream ÷ frame by frame")
    for name, rows in res:
        print(f"{name}")
        for v, r in zip(VARIANTS, rows):
            print(f"  {v:34s} " + " ".join(f"{x:.4f}" for x in r))
    r = np.array([rows for _, rows in res])
    for i, v in enumerate(VARIANTS):
        print(f"mean {v:34s} " + " ".join(f"{k} {x:.4f}" for k, x in zip(KEYS, r[:, i].mean(0))))


if __name__ == "__main__":
    main()
