"""Why every model makes the near-clean crops of Baby1 and Baby3 worse (near_clean_2006.py: ratio up to 3.6 at
sigma 0.3): the frozen `full` model with the singular test's neighbour-support tolerance (`singular.support_tol`, in
noise sigma; 2 by default) raised, and without the edge steps. Fitting split only (2006 scenes); a diagnosis, nothing
shipped.

    python docs/measurements/issue27-tiers/tier-refiners/near_clean_support_tol.py
"""
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "default-tier"))
from near_clean_2006 import near_clean_crop, rmse  # noqa: E402  (the crops of that script)

from torch_depth_sr import DepthRestorer, restore_depth  # noqa: E402

VARIANTS = (("full", {}), ("tol3", {"singular": {"support_tol": 3.0}}), ("tol4", {"singular": {"support_tol": 4.0}}),
            ("no-edge-steps", {"edge_snap": None, "edge_refit": None}))
torch.set_num_threads(1)
for sc in ("Baby1", "Baby3", "Cloth3"):
    depth, rgb, m, noisy = near_clean_crop(sc, 0.3)
    line = f"{sc} input {rmse(noisy, depth, m):.3f}"
    for name, kw in VARIANTS:
        o = restore_depth(noisy, rgb, model=DepthRestorer(**kw))
        e = np.abs(o.astype(np.float64) - depth)[m]
        line += f" | {name} {rmse(o, depth, m):.3f} n>2 {(e > 2).sum()}"
    print(line, flush=True)
