"""The do-no-harm test's checks (tests/test_do_no_harm.py, the speed-tier test) on candidates before they ship: a
synthetic 8-bit scene at noise sigma 0.3 and 1, and the Art crop clean and at sigma 0.3 (the restored RMSE against the
input's; each must be lower). Art is a held-out scene: this check is a constraint every tier must meet, not a score.

    python docs/measurements/issue27-tiers/eleventh-stop/harm_check.py preset:default runs/default-warm/best
"""
import sys

import cv2
import numpy as np
import torch

from torch_depth_sr import DepthRestorer, restore_depth
from torch_depth_sr._data_root import data_root
from torch_depth_sr.datasets.synthetic import make_scene


def clean_scene(h: int = 96, w: int = 128, seed: int = 0):
    """The test's clean 8-bit synthetic scene and its colour (tests/test_do_no_harm.py ``_clean_scene``)."""
    s = make_scene(h, w, seed=seed)
    depth = s["gt"][0].round().clamp(1, 255).numpy().astype(np.uint8)
    return depth, (s["rgb"].permute(1, 2, 0).numpy() * 255).round().astype(np.uint8)


def rmse(a, b, m) -> float:
    return float(np.sqrt(((a.astype(np.float64) - b.astype(np.float64))[m] ** 2).mean()))


torch.set_num_threads(1)
for spec in sys.argv[1:]:
    model = DepthRestorer.from_preset(spec[7:]) if spec.startswith("preset:") else DepthRestorer.load(spec)
    depth, rgb = clean_scene(seed=2)
    rng = np.random.default_rng(0)
    line = spec
    for sigma in (0.3, 1.0):
        noisy = (depth + sigma * rng.standard_normal(depth.shape)).astype(np.float32)
        m = depth > 0
        line += f" | synth σ{sigma}: {rmse(restore_depth(noisy, rgb, model=model), depth, m):.4f} vs {rmse(noisy, depth, m):.4f}"
    art = str(data_root() / "middlebury2005" / "Art")
    depth = cv2.imread(art + "/disp1.png", cv2.IMREAD_UNCHANGED)[100:220, 150:310]
    rgb = cv2.imread(art + "/view1.png")[100:220, 150:310, ::-1].copy()
    m = depth > 0
    clean_ok = np.array_equal(restore_depth(depth, rgb, model=model)[m], depth[m])
    noisy = (depth + 0.3 * np.random.default_rng(0).standard_normal(depth.shape)).astype(np.float32)
    noisy[~m] = 0
    line += f" | Art clean unchanged {clean_ok} | Art σ0.3: {rmse(restore_depth(noisy, rgb, model=model), depth, m):.4f} vs {rmse(noisy, depth, m):.4f}"
    print(line, flush=True)
