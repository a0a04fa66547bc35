"""The grids behind the edge-snapping defaults, on the outputs save_outputs.py wrote (the 2006 scenes only).

    python docs/measurements/edge-snap/grid.py snap    # passes × window × share × colour σ
    python docs/measurements/edge-snap/grid.py refit   # after one snapping pass: radius × band × edge × colour σ

Figures are post hoc (on the saved output, after the fidelity band); the model runs both steps before the band, so
its figures differ a little (README, model choices). Flying + impulse left, RMSE, MAE: means over scenes.
"""
import itertools
import os
import sys

import numpy as np
import torch
import torch.nn.functional as F

from torch_depth_sr.edge_snap import refit_to_measurements, sided_median, snap_to_sides

OUT = os.environ.get("OUT", "/tmp/edge-snap")
SCENES = sorted(f[:-4] for f in os.listdir(OUT) if f.endswith(".npz"))  # what save_outputs.py wrote: 2006 scenes only


def stats(p, z):
    gt, fi, known = z["gt"], z["F"] | z["I"], z["gt"] > 0
    e = np.abs(p - gt)
    return np.array([(e[fi] > 3).mean(), np.sqrt(((p - gt)[known] ** 2).mean()), e[known].mean()])


res, base = {}, []
for name in SCENES:
    z = np.load(f"{OUT}/{name}.npz")
    rgb, x = torch.from_numpy(z["rgb"])[None].double(), torch.from_numpy(z["out"])[None, None].double()
    base.append(stats(z["out"], z))
    if sys.argv[1] == "snap":
        for r, share, sc in itertools.product((2, 3), (0.5, 0.6, 0.7, 0.8, 0.9), (0.1, 0.235)):
            v = x
            for passes in (1, 2):
                m, sh = sided_median(v, rgb, r, sc)
                v = torch.where(sh > share, m, v)
                res.setdefault((passes, r, share, sc), []).append(stats(v[0, 0].numpy(), z))
    else:
        sigma = 5.0  # the sensor track's noise; the model passes x in σ̂ units, here grey levels
        y = torch.from_numpy(z["yin"])[None, None].double()
        s = snap_to_sides(x, rgb, 1)
        for r, band, edge, sc in itertools.product((4, 5, 7), (1.5, 2, 3), (1, 2, 3), (0.1, 0.235)):
            p = refit_to_measurements(s, y, (y > 0).double(), rgb, r, band * sigma, edge * sigma, sc)
            res.setdefault((r, band, edge, sc), []).append(stats(p[0, 0].numpy(), z))
print("without: flying+impulse left %.4f  RMSE %.4f  MAE %.4f" % tuple(np.mean(base, 0)))
for k, v in sorted(res.items(), key=lambda t: np.mean(t[1], 0)[0]):
    print(k, "flying+impulse left %.4f  RMSE %.4f  MAE %.4f" % tuple(np.mean(v, 0)))
