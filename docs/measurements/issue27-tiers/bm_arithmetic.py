"""Issue 27 item 2: what the exact block-matching kernel spends on the search itself (distances by shift and box
filter) against the running top-k selection, at 640x480, one thread: the same window with k = 1 (selection nearly
free) and k = 10, 20, 40, and the windows of the tiers (15x15 for the default, 7x7 for fast).

    OMP_NUM_THREADS=1 python docs/measurements/issue27-tiers/bm_arithmetic.py
"""
import time

import torch

from torch_depth_sr.block_matching import block_match
from torch_depth_sr.evaluation.speed import make_inputs

torch.set_num_threads(1)
y, rgb, _ = make_inputs(480, 640, 1)
x = y / 5.0
trust = (y > 0).float()
print("window  k   seconds (min of 3, 1 thread)")
for window in (15, 7):
    for k in (1, 10, 20, 40):
        if k > (window // 2 + 1) ** 2 - 1:  # more than a corner pixel has
            continue
        block_match(x, rgb, trust, block_size=3, search_window=window, k=k, color_weight=400.0)
        t = []
        for _ in range(3):
            t0 = time.perf_counter()
            block_match(x, rgb, trust, block_size=3, search_window=window, k=k, color_weight=400.0)
            t.append(time.perf_counter() - t0)
        print(f"{window:2d}x{window:<2d} {k:3d}  {min(t):.3f}", flush=True)
