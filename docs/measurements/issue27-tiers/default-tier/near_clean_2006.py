"""No harm on near-clean input, on the fitting split: 120x160 crops of the eleven 2006 scenes (8-bit disparity,
sigma 0.3 and 0.5 grey levels of noise): restored RMSE against the input's, per model."""
import sys

import cv2
import numpy as np
import torch

from torch_depth_sr import DepthRestorer, restore_depth
from torch_depth_sr._data_root import data_root

SC = ("Baby1", "Baby2", "Baby3", "Cloth1", "Cloth2", "Cloth3", "Cloth4", "Midd1", "Midd2", "Wood1", "Wood2")


def near_clean_crop(scene: str, sigma: float):
    """The central 120x160 crop of a 2006 scene: its disparity, colour, measured mask and the disparity with noise
    ``sigma`` (seed 0) at the measured pixels."""
    d = data_root() / "middlebury2006" / scene
    depth = cv2.imread(str(d / "disp1.png"), cv2.IMREAD_UNCHANGED)
    rgb = cv2.imread(str(d / "view1.png"))[:, :, ::-1]
    h, w = depth.shape
    y0, x0 = h // 2 - 60, w // 2 - 80
    depth, rgb = depth[y0:y0 + 120, x0:x0 + 160], rgb[y0:y0 + 120, x0:x0 + 160].copy()
    m = depth > 0
    noisy = (depth + sigma * np.random.default_rng(0).standard_normal(depth.shape)).astype(np.float32)
    noisy[~m] = 0
    return depth, rgb, m, noisy


def rmse(a, depth, m) -> float:
    return float(np.sqrt(np.mean((a.astype(np.float64)[m] - depth[m]) ** 2)))


def main() -> None:
    torch.set_num_threads(1)
    models = {a: (DepthRestorer() if a == "full" else DepthRestorer.load(a)) for a in sys.argv[1:]}
    for sig in (0.3, 0.5):
        worse = {a: 0 for a in models}
        ratio = {a: [] for a in models}
        for sc in SC:
            depth, rgb, m, noisy = near_clean_crop(sc, sig)
            for a, mod in models.items():
                q = rmse(restore_depth(noisy, rgb, model=mod), depth, m) / rmse(noisy, depth, m)
                ratio[a].append(q)
                worse[a] += q >= 1
        for a in models:
            print(f"sigma {sig} {a[-30:]:30s} worse on {worse[a]}/11, mean ratio {np.mean(ratio[a]):.4f}, "
                  f"max {max(ratio[a]):.3f}", flush=True)


if __name__ == "__main__":
    main()
