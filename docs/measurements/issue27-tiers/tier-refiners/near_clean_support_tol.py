"""Why every model makes the near-clean crops of Baby1 and Baby3 worse (near_clean_2006.py: ratio up to 3.6 at
sigma 0.3): the frozen `full` model with the singular test's neighbour-support tolerance (`singular.support_tol`, in
noise sigma; 2 by default) raised, and without the edge steps. Fitting split only (2006 scenes); a diagnosis, nothing
shipped.

    python docs/measurements/issue27-tiers/tier-refiners/near_clean_support_tol.py
"""
import sys, cv2, numpy as np, torch
from torch_depth_sr import DepthRestorer, restore_depth
from torch_depth_sr._data_root import data_root
torch.set_num_threads(1)
for sc in ("Baby1", "Baby3", "Cloth3"):
    d = data_root() / "middlebury2006" / sc
    depth = cv2.imread(str(d / "disp1.png"), cv2.IMREAD_UNCHANGED)
    rgb = cv2.imread(str(d / "view1.png"))[:, :, ::-1]
    h, w = depth.shape; y0, x0 = h // 2 - 60, w // 2 - 80
    depth, rgb = depth[y0:y0 + 120, x0:x0 + 160], rgb[y0:y0 + 120, x0:x0 + 160].copy()
    m = depth > 0
    noisy = (depth + 0.3 * np.random.default_rng(0).standard_normal(depth.shape)).astype(np.float32); noisy[~m] = 0
    r = lambda a: float(np.sqrt(np.mean((a.astype(np.float64)[m] - depth[m]) ** 2)))
    line = f"{sc} input {r(noisy):.3f}"
    for name, kw in [("full", {}), ("tol3", {"singular": {"support_tol": 3.0}}), ("tol4", {"singular": {"support_tol": 4.0}}), ("no-edge-steps", {"edge_snap": None, "edge_refit": None})]:
        o = restore_depth(noisy, rgb, model=DepthRestorer(**kw))
        e = np.abs(o.astype(np.float64) - depth)[m]
        line += f" | {name} {r(o):.3f} n>2 {(e>2).sum()}"
    print(line, flush=True)
