"""Issue 28, tried and not shipped: a noise unit of the change test that an edge cannot inflate (a diagnosis of
``trail_mechanism.txt``; the stream's code is unchanged, this script swaps the spread functions the stream restorer
calls for the time of the run).

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/nineteenth-stop/tried_trimmed_unit.py
        [--unit trimmed|clipped] [--trim 3] [--set tuning|fresh]

The stream keeps as its noise unit the window mean of ``|y − x|`` (``change.local_spread``), and where static at
least the frame-to-frame change, remembered (``change.remembered_spread``). ``--unit trimmed`` leaves out of each
mean the residuals above ``trim`` times the plain window mean at their pixel (an edge the estimate placed off, an
edge that moved: a minority of the window), in both. ``--unit clipped`` clips each residual at ``trim`` times the
previous frame's unit at its pixel before the means (a unit grows by at most that factor a frame; the first frame's
is the shipped one). Per sequence the stream track's scores divided by frame-by-frame restoration's, as
``fresh_seeds.py``: ``--set tuning`` the tuning sequences, ``--set fresh`` the recipes with seeds 200–205.
"""
from __future__ import annotations

import argparse

import numpy as np
import torch

from torch_depth_sr import restore_depth
from torch_depth_sr.datasets.sequences import TUNING_SEQUENCES, make_sequence, recipe_sequences
from torch_depth_sr.evaluation.stream import regions, synthetic_metrics
from torch_depth_sr.stream import StreamRestorer, change, default_stream_model
from torch_depth_sr.stream import frame as stream_frame

from fresh_seeds import restored_frames  # this folder's script (its folder is on the path)

KEYS = ("rmse", "flicker", "trail")


def trimmed_spread(y, observed, x, window, trim):
    m = (observed > 0).to(y.dtype)
    r = torch.where(m > 0, (y - x).abs(), torch.zeros_like(x))
    num, den = change._window_mean(r, window, m)
    plain = torch.where(den > 0, num / den.clamp_min(1e-12), torch.zeros_like(num))
    keep = m * (r <= trim * plain).to(y.dtype)
    num, den = change._window_mean(r * keep, window, keep)
    return torch.where(den > 0, num / den.clamp_min(1e-12), plain)



def clipped_spread(y, observed, x, limit, window):
    m = (observed > 0).to(y.dtype)
    r = torch.where(m > 0, torch.minimum((y - x).abs(), limit), torch.zeros_like(x))
    num, den = change._window_mean(r, window, m)
    return torch.where(den > 0, num / den.clamp_min(1e-12), torch.zeros_like(num))

def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--unit", choices=("trimmed", "clipped"), default="trimmed")
    p.add_argument("--trim", type=float, default=3.0, help="trimmed: 3 (the default); clipped: try 4 (outlier_test)")
    p.add_argument("--set", choices=("tuning", "fresh"), default="tuning")
    a = p.parse_args()
    torch.set_num_threads(1)

    def local_spread(y, observed, x, window):
        if a.unit == "clipped":
            return change.local_spread(y, observed, x, window)
        return trimmed_spread(y, observed, x, window, a.trim)

    def remembered_spread(y, observed, x, past, past_spread, static, window, memory):
        if a.unit == "clipped":
            limit = a.trim * past_spread
            spread, moved = (clipped_spread(y, observed, v, limit, window) for v in (x, past))
        else:
            spread, moved = (trimmed_spread(y, observed, v, window, a.trim) for v in (x, past))
        remembered = torch.maximum(moved, memory * past_spread)
        return torch.where(static, torch.maximum(spread, remembered), spread)

    model = default_stream_model()
    specs = TUNING_SEQUENCES if a.set == "tuning" else recipe_sequences(range(200, 206))
    rows = {"shipped": [], a.unit: []}
    for spec in specs:
        seq = make_sequence(spec, frames=30, height=120, width=160)
        reg = regions(seq)
        base = synthetic_metrics(restored_frames(lambda d, c: restore_depth(d, c, model=model), seq), seq, reg)
        cells = []
        for name in rows:
            shipped = stream_frame.local_spread, stream_frame.remembered_spread
            if name == a.unit:
                stream_frame.local_spread, stream_frame.remembered_spread = local_spread, remembered_spread
            try:
                m = synthetic_metrics(restored_frames(StreamRestorer(model).step, seq), seq, reg)
            finally:
                stream_frame.local_spread, stream_frame.remembered_spread = shipped
            r = [m[k] / base[k] for k in KEYS]
            rows[name].append(r)
            cells.append(f"{name}: " + " ".join(f"{k} {v:.4f}" for k, v in zip(KEYS, r)))
        print(f"{spec.name:22s} " + " | ".join(cells), flush=True)
    for name, r in rows.items():
        print(f"mean {name}: " + " ".join(f"{k} {v:.4f}" for k, v in zip(KEYS, np.mean(r, 0))))


if __name__ == "__main__":
    main()
