"""Issue 28, thirty-first stop: where the drift test fires on the real static tabletop (a reporting sequence: looked
at after the test broke its static region's figures, to say why; the variants tried against it here were not
shipped, nor was the test).

The stream runs with the drift test at ``--clip`` (the bound on one measurement's departure, in noise units) and
``--test`` (z-score). For each frame: the share of the static region's pixels (the top 150 rows, which never move)
that the drift test alone calls changed, and there the mean of ``|y − m|`` (the measurement minus its run's mean) in
the frame's normalised units and in noise units.

    OMP_NUM_THREADS=2 python docs/measurements/issue28-stream/thirty-first-stop/drift_on_tabletop.py --clip 1 --test 4

Runs on ``e78049c`` with ``tried_drift_test.patch`` applied (the clip read from ``DRIFT_CLIP``, which this script
sets; ``DRIFT_COLOUR`` and ``DRIFT_MEMORY`` as in ``drift_on_tabletop_shares.txt``, which gives the mean shares;
``drift_on_tabletop_clip*.txt`` the frames of two of them).
"""
from __future__ import annotations

import argparse
import os

import numpy as np
import torch

p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
p.add_argument("--clip", default="1.0")
p.add_argument("--test", type=float, default=4.0)
p.add_argument("--frames", type=int, default=30)
a = p.parse_args()
os.environ["DRIFT_CLIP"] = a.clip

import torch_depth_sr.stream.change as change  # noqa: E402
from torch_depth_sr._data_root import data_root  # noqa: E402
from torch_depth_sr.evaluation.stream import _load_real  # noqa: E402
from torch_depth_sr.stream import StreamRestorer, default_stream_model  # noqa: E402

SEEN: list = []
_DRIFTING = change.drifting


def drifting(y, observed, run_mean, has_run, noise, test):
    out = _DRIFTING(y, observed, run_mean, has_run, noise, test)
    SEEN.append((out[0, 0].numpy().copy(), ((y - run_mean) * (observed > 0) * has_run)[0, 0].numpy().copy(),
                 noise[0, 0].numpy().copy()))
    return out


change.drifting = drifting
torch.set_num_threads(2)
depth, rgb = _load_real(data_root(), "realsense_static_tabletop", a.frames, 2)
stream = StreamRestorer(default_stream_model(), {"drift_test": a.test})
scales = []
with torch.no_grad():
    for t in range(len(depth)):
        r = stream.step(depth[t], rgb[t], return_details=True)
rows = 75  # the static region at stride 2
print(f"clip {a.clip}, test {a.test}: frame, share of the static region the drift test calls changed, "
      f"mean departure there (normalised units / noise units)")
for t, (flag, dep, unit) in enumerate(SEEN, 1):
    f = flag[:rows]
    if f.any():
        far = np.abs(dep[:rows][f])
        print(f"  {t:3d}  {f.mean():.4f}  {far.mean():.4f} / {(far / unit[:rows][f]).mean():.2f}")
    else:
        print(f"  {t:3d}  0")
