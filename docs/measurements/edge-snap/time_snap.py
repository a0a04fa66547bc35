"""Time one edge-snapping pass (torch_depth_sr.edge_snap.snap_to_sides) alone, float32, best of three.

    OMP_NUM_THREADS=1 python docs/measurements/edge-snap/time_snap.py
"""
import time

import torch

from torch_depth_sr.edge_snap import snap_to_sides

for h, w in ((370, 463), (480, 640), (1088, 1376)):
    g = torch.Generator().manual_seed(0)
    x, rgb = torch.rand(1, 1, h, w, generator=g) * 100, torch.rand(1, 3, h, w, generator=g)
    best = float("inf")
    for _ in range(3):
        t = time.perf_counter()
        snap_to_sides(x, rgb, rounds=1)
        best = min(best, time.perf_counter() - t)
    print(f"{w}x{h}: {best:.3f} s")
