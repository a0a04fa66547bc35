"""Issue 28, thirty-second stop: the stream's wrong fills (``fill="trusted"``, more than 5 % off the truth) in the
holes of the trail region at 480×640, by what the stream did with each hole: filled from a confident past (static,
evidence ≥ ``fill_evidence``), a hole in the previous frame too (its previous verdict may be held), or neither; and
frame by frame's on the same pixels. One sequence of the ``static-busy`` recipe (the seed: 3 is the evaluated one).

    OMP_NUM_THREADS=2 python docs/measurements/issue28-stream/thirty-second-stop/hole_verdicts.py 404 \
        --settings "{'unmeasured_frames': 2.0}"
"""
from __future__ import annotations

import argparse
import ast

import numpy as np
import torch

from torch_depth_sr import restore_depth
from torch_depth_sr.datasets.sequences import make_sequence, recipe_sequences
from torch_depth_sr.evaluation.stream import regions
from torch_depth_sr.stream import StreamRestorer, default_stream_model


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("seed", type=int)
    p.add_argument("--recipe", default="static-busy")
    p.add_argument("--settings", default="{}", help="StreamConfig overrides as a Python dict literal")
    a = p.parse_args()
    spec = next(s for s in recipe_sequences([a.seed]) if s.name.split("@")[0] == a.recipe)
    seq = make_sequence(spec, frames=30, height=480, width=640)
    gt, trail = seq["gt"][:, 0].astype(np.float64), regions(seq)["trail"]
    model = default_stream_model().eval()
    stream = StreamRestorer(model, ast.literal_eval(a.settings), fill="trusted")
    rows: dict = {}
    with torch.no_grad():
        for t in range(len(gt)):
            depth, rgb = seq["depth"][t].astype(np.float32), seq["rgb"][t]
            before = stream.state
            s = stream.step(depth, rgb, return_details=True)
            f = np.nan_to_num(np.asarray(restore_depth(depth, rgb, model=model, fill="trusted"))[0])
            if before is None:
                continue
            out = np.nan_to_num(s.depth[0])
            evidence, was_hole = before.evidence[0, 0].numpy(), before.hole[0, 0].numpy()
            hole = depth[0] <= 0
            past = hole & (s.static[0] > 0) & (evidence >= stream.settings.fill_evidence)
            for name, m in (("from a confident past", past), ("a hole before too", hole & ~past & was_hole),
                            ("neither", hole & ~past & ~was_hole)):
                m = m & trail[t]
                r = rows.setdefault(name, [0, 0, 0])
                r[0] += int((m & (out > 0) & (np.abs(out - gt[t]) > 0.05 * gt[t])).sum())
                r[1] += int((m & (f > 0) & (np.abs(f - gt[t]) > 0.05 * gt[t])).sum())
                r[2] += int(m.sum())
    print(f"{spec.name} at 480x640, fill='trusted', settings {a.settings}: wrong values in the trail's holes")
    for name, (ns, nf, n) in rows.items():
        print(f"  {name:24s} stream {ns:6d}  frame by frame {nf:6d}  of {n} pixel-frames")


if __name__ == "__main__":
    main()
