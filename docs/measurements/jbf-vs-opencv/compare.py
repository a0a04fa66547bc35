"""Ours (torch_depth_sr.baselines.jbf_denoise, L1 colour distance as OpenCV) against OpenCV's outputs saved by
opencv_jbf.py, same inputs, same settings, on the scenes it saved (Art, Teddy held out; Baby1, Cloth2 of 2006).
Prints per scene and setting: RMSE over GT-known pixels of each, and the mean / 99.9th percentile / max of
|ours - OpenCV|."""
import os
import re
from pathlib import Path

import numpy as np
import torch

from torch_depth_sr.baselines import jbf_denoise

D = Path(os.environ.get("JBF_CHECK_DIR", "/tmp/jbf-check"))
torch.set_num_threads(1)
for f in sorted(D.glob("*_ocv_*.npy")):
    name, track, setting = re.match(r"(\w+?)_(paper|sensor)_ocv_(.*)\.npy", f.name).groups()
    ss, sc, it, rej = setting.split("_")
    y = np.load(D / f"{name}_{track}_y.npy")
    gt, known = np.load(D / f"{name}_gt.npy"), np.load(D / f"{name}_m.npy") > 0
    rgb = torch.from_numpy(np.load(D / f"{name}_rgb.npy") / 255.0).permute(2, 0, 1)[None].float()
    yt = torch.from_numpy(y)[None, None]
    ours = jbf_denoise(yt, rgb, (yt > 0).float(), float(ss), float(sc), int(it), None if rej == "None" else float(rej),
                       color_distance_type="l1")[0, 0].numpy()
    ocv = np.load(f)
    r = lambda p: float(np.sqrt(((p - gt)[known] ** 2).mean()))
    d = np.abs(ours - ocv)[known]
    print(f"{track:6s} {name:7s} (σs {ss}, σc {sc}, it {it}, reject {rej}): RMSE opencv {r(ocv):.3f} ours {r(ours):.3f}; "
          f"|ours-opencv| mean {d.mean():.3f} p99.9 {np.percentile(d, 99.9):.2f} max {d.max():.2f}")
