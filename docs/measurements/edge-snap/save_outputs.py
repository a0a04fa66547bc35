"""Run `full` with snapping and the refit off on `sensor` inputs of some scenes and save what the grids need.

    OMP_NUM_THREADS=2 python docs/measurements/edge-snap/save_outputs.py Baby1,Baby2,...  # -> $OUT (default /tmp/edge-snap)

Prints, per scene, why flying pixels are left (trusted by the singular test? between the two sides?).
"""
import json
import os
import sys

import cv2
import numpy as np
import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr._data_root import require_data_root
from torch_depth_sr.evaluation.bench import _samples

OUT = os.environ.get("OUT", "/tmp/edge-snap")
os.makedirs(OUT, exist_ok=True)
model = DepthRestorer(edge_snap=None, edge_refit=None)
for r, s in _samples("sensor", require_data_root(), sys.argv[1].split(","), None):
    y, rgb = s["depth"][None], s["rgb"][None]
    with torch.no_grad():
        res = model.restore_with_details(y, rgb)
    out, gt = res.depth[0, 0].numpy(), s["gt"][0].numpy()
    fly, imp, edges, holes = (s[k][0].numpy() > 0 for k in ("flying", "impulse", "edges", "holes"))
    trusted = res.trusted[0, 0].numpy() > 0.5
    known = gt > 0
    k5 = np.ones((5, 5), np.uint8)
    nmin = cv2.erode(np.where(known, gt, np.inf).astype(np.float32), k5)
    nmax = cv2.dilate(np.where(known, gt, -np.inf).astype(np.float32), k5)
    left = fly & (np.abs(out - gt) > 3)
    other = known & ~fly & ~imp & ~holes & edges
    print(json.dumps({"scene": r.name, "flying_left": round(float(left.sum() / fly.sum()), 3),
                      "left_trusted": round(float((left & trusted).sum() / max(left.sum(), 1)), 3),
                      "left_between_sides": round(float((left & (out > nmin + 3) & (out < nmax - 3)).sum()
                                                        / max(left.sum(), 1)), 3),
                      "other_edge_pixels_left": round(float((other & (np.abs(out - gt) > 3)).sum() / other.sum()), 3)}))
    np.savez_compressed(f"{OUT}/{r.name}.npz", out=out, gt=gt, F=fly, I=imp, E=edges, H=holes, tr=trusted,
                        yin=y[0, 0].numpy(), rgb=s["rgb"].numpy())
