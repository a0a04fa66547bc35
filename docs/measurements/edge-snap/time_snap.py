"""Time the two edge steps alone, float32, best of three, on procedural scenes (make_scene) with σ = 5 noise:
one snapping pass (snap_to_sides) and the refit to the measurements (refit_to_measurements, which only visits
pixels near depth edges: their share is printed).

    OMP_NUM_THREADS=1 python docs/measurements/edge-snap/time_snap.py
"""
import time

import torch
import torch.nn.functional as F

from torch_depth_sr.datasets.synthetic import make_scene
from torch_depth_sr.edge_snap import refit_to_measurements, snap_to_sides


def best_of_three(fn):
    best = float("inf")
    for _ in range(3):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


for h, w in ((370, 463), (480, 640), (1088, 1376)):
    s = make_scene(h, w, seed=0)
    g = torch.Generator().manual_seed(0)
    x = (s["gt"] / 5.0)[None]  # in noise-σ units, as the model passes it
    y = x + torch.randn(x.shape, generator=g)
    rgb = s["rgb"][None]
    near = float(((F.max_pool2d(x, 5, 1, 2) + F.max_pool2d(-x, 5, 1, 2)) > 2.0).float().mean())
    t_snap = best_of_three(lambda: snap_to_sides(x, rgb, rounds=1))
    t_refit = best_of_three(lambda: refit_to_measurements(x, y, torch.ones_like(y), rgb))
    print(f"{w}x{h}: snap {t_snap:.3f} s, refit {t_refit:.3f} s ({100 * near:.1f} % of the pixels near an edge)")
