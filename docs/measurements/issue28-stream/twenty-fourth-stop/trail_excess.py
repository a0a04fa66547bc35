"""Issue 28, twenty-fourth stop: where the stream's trail error exceeds frame-by-frame restoration's at 480×640.

The trail score is the RMS of the error over the trail region (a mover's pixels grown by 2 px, and the pixels it
left in the last four frames), so a few pixels with errors the size of a depth gap decide it. Here each sequence is
restored by both, and the difference of squared errors, ``e_stream² − e_frame²``, is summed over the trail region in
groups of pixels, divided by the region's size: each row is that group's share of the difference of the two
mean squared errors (the rows of one split sum to it). Groups: holes of the input; measured pixels the stream's change
test called static or changed; measured pixels trusted by both, by the stream only, by frame-by-frame only, by
neither; and the stream-only trusted ones split again by change and by whether the measurement is a gross error
(``|y − gt| > 5 σ̂``, σ̂ the frame's 1.4826 × median ``|y − gt|``: a flying pixel or an impulse).

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-fourth-stop/trail_excess.py --size 480x640 \
        [--seeds 303]

Fitting scenes only (the three tuning sequences): it reads ground truth to sort pixels, which the stream never does.
"""
from __future__ import annotations

import argparse
from collections import defaultdict
from multiprocessing import Pool

import numpy as np
import torch

from torch_depth_sr import restore_depth
from torch_depth_sr.datasets.sequences import TUNING_SEQUENCES, make_sequence, recipe_sequences
from torch_depth_sr.evaluation.stream import regions
from torch_depth_sr.stream import StreamRestorer, default_stream_model


def _sequence(job) -> tuple[str, dict, float, float]:
    spec, size = job
    torch.set_num_threads(1)
    seq = make_sequence(spec, frames=30, height=size[0], width=size[1])
    trail = regions(seq)["trail"]
    model = default_stream_model().eval()
    stream = StreamRestorer(model)
    gt = seq["gt"][:, 0].astype(np.float64)
    sums: dict = defaultdict(float)
    se_stream = se_frame = 0.0
    with torch.no_grad():
        for t in range(len(gt)):
            depth, rgb = seq["depth"][t].astype(np.float32), seq["rgb"][t]
            s = stream.step(depth, rgb, return_details=True)
            f = restore_depth(depth, rgb, model=model, return_details=True)
            region = trail[t]
            if not region.any():
                continue
            es = (np.nan_to_num(s.depth[0]) - gt[t]) ** 2
            ef = (np.nan_to_num(f.depth[0]) - gt[t]) ** 2
            diff = np.where(region, es - ef, 0.0)
            se_stream, se_frame = se_stream + es[region].sum(), se_frame + ef[region].sum()
            y = depth[0]
            hole = y <= 0
            static = s.static[0] > 0
            by_stream, by_frame = (s.trusted[0] > 0) & ~hole, (f.trusted[0] > 0) & ~hole
            err = np.abs(y - gt[t])
            gross = ~hole & (err > 5 * 1.4826 * np.median(err[~hole]))
            groups = {"hole": hole, "measured, static": ~hole & static, "measured, changed": ~hole & ~static,
                      "trusted by both": by_stream & by_frame, "trusted by the stream only": by_stream & ~by_frame,
                      "trusted by frame-by-frame only": ~by_stream & by_frame,
                      "trusted by neither": ~hole & ~by_stream & ~by_frame}
            only = by_stream & ~by_frame
            for change, cm in (("static", static), ("changed", ~static)):
                for kind, km in (("gross", gross), ("not gross", ~gross)):
                    groups[f"  stream only, {change}, {kind}"] = only & cm & km
            for name, mask in groups.items():
                sums[name] += diff[mask].sum()
                sums["n " + name] += (region & mask).sum()
            sums["pixels"] += region.sum()
    n = sums.pop("pixels")
    return spec.name, {k: (v if k.startswith("n ") else v / n) for k, v in sums.items()}, np.sqrt(se_stream / n), \
        np.sqrt(se_frame / n)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", default="480x640")
    p.add_argument("--processes", type=int, default=2)
    p.add_argument("--seeds", type=int, nargs="+", help="the three recipes with these seeds instead of the tuning "
                   "sequences (fitting seeds only: 300-303, 400-409)")
    a = p.parse_args()
    size = tuple(int(t) for t in a.size.split("x"))
    specs = TUNING_SEQUENCES if not a.seeds else recipe_sequences(a.seeds)
    with Pool(a.processes) as pool:
        results = pool.map(_sequence, [(s, size) for s in specs], chunksize=1)
    for name, rows, trail_stream, trail_frame in results:
        print(f"{name} at {a.size}: trail {trail_stream:.2f} stream, {trail_frame:.2f} frame by frame; "
              f"MSE difference {trail_stream ** 2 - trail_frame ** 2:+.2f}, by group (pixel-frames):")
        for k, v in rows.items():
            if not k.startswith("n "):
                print(f"  {k:40s} {v:+9.2f}   ({int(rows['n ' + k])})")


if __name__ == "__main__":
    main()
