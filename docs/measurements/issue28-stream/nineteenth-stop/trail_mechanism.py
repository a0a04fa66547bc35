"""Issue 28: how a mover leaves a trail in ``static-2movers@202`` (``fresh_seeds.py``), one image row over three frames
(a diagnosis; nothing is fitted or changed: the two wrappers below only record what the stream's change test and
run update receive).

    python docs/measurements/issue28-stream/nineteenth-stop/trail_mechanism.py [--seed 202] [--frame 25] [--row 110]
        [--cols 147 160] [--join-cap none]

Per frame, along the row: the truth, the raw measurement, the previous restored frame (the change test's reference),
the change test's noise unit (depth units), its verdict, what the model sees as the measurement (the run's mean on
static pixels; the offset where a value was dropped as an outlier in time), the temporal prior's weight, and the
stream's output beside frame-by-frame restoration's. ``--join-cap`` (default ``none``: the stream as it was when
this trace was made, before ``StreamConfig.join_cap``; ``80``: today's default).
"""
from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np
import torch

from torch_depth_sr import restore_depth
from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, make_sequence
from torch_depth_sr.stream import StreamRestorer, default_stream_model
from torch_depth_sr.stream import frame as stream_frame


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--seed", type=int, default=202)
    p.add_argument("--frame", type=int, default=25)
    p.add_argument("--row", type=int, default=110)
    p.add_argument("--cols", type=int, nargs=2, default=(147, 160))
    p.add_argument("--join-cap", default="none", help="StreamConfig.join_cap: none (the default here) or a number")
    a = p.parse_args()
    torch.set_num_threads(1)
    seen: dict = {}
    change_test, join_runs = stream_frame.change_test, stream_frame.join_runs

    def recorded_change_test(y, observed, target, noise, *args):
        out = change_test(y, observed, target, noise, *args)
        seen.update(target=target, noise=noise, changed=out.changed)
        return out

    def recorded_join_runs(*args):
        out = join_runs(*args)
        seen.update(runs=out, offset=args[-3], scale=args[-2])
        return out

    stream_frame.change_test, stream_frame.join_runs = recorded_change_test, recorded_join_runs
    spec = replace(STREAM_SEQUENCES[0], name=f"static-2movers@{a.seed}", seed=a.seed)
    seq = make_sequence(spec, frames=a.frame + 1, height=120, width=160)
    model = default_stream_model()
    stream = StreamRestorer(model, {"join_cap": None if a.join_cap == "none" else float(a.join_cap)})
    c0, c1 = a.cols

    def show(name, v, fmt="{:6.0f}"):
        v = np.asarray(v, dtype=np.float64).reshape(-1, *np.shape(v)[-2:])[0]
        print(f"  {name:28s}" + " ".join(fmt.format(x) for x in v[a.row, c0:c1]))

    print(f"{spec.name}, row {a.row}, columns {c0}–{c1 - 1} (depth in mm)")
    with torch.no_grad():
        for t in range(a.frame + 1):
            depth, rgb = seq["depth"][t, 0], torch.from_numpy(seq["rgb"][t])
            out = stream.step(depth, rgb)
            if t < a.frame - 2:
                continue
            scale, offset = seen["scale"].view(-1, 1, 1, 1), seen["offset"].view(-1, 1, 1, 1)
            runs = seen["runs"]
            print(f"frame {t}")
            show("truth", seq["gt"][t, 0])
            show("raw", depth)
            show("previous restored frame", seen["target"] * scale + offset)
            show("noise unit of the change test", seen["noise"] * scale)
            show("changed (change test)", seen["changed"].float())
            show("model's measurement", runs.y * scale + offset)
            show("temporal prior weight", runs.weight, "{:6.2f}")
            show("stream", out)
            show("frame by frame", restore_depth(depth, rgb, model=model))


if __name__ == "__main__":
    main()
