"""Write the benchmark's exact degraded inputs (tracks paper and sensor, every scene) as .npy for the OpenCV check.

Same generator as ``torch-depth-sr bench`` (same seeds, inputs below 0 clamped to 0 = missing).
Files in $JBF_CHECK_DIR (default /tmp/jbf-check): <scene>_<track>_y.npy, <scene>_gt.npy, <scene>_m.npy,
<scene>_rgb.npy (H,W,3 float32 on 0-255, RGB order).
"""
import os
from pathlib import Path

import numpy as np

from torch_depth_sr._data_root import data_root
from torch_depth_sr.evaluation.bench import _samples

OUT = Path(os.environ.get("JBF_CHECK_DIR", "/tmp/jbf-check"))
OUT.mkdir(parents=True, exist_ok=True)
for track in ("paper", "sensor"):
    for rec, s in _samples(track, data_root(), None, None):
        np.save(OUT / f"{rec.name}_{track}_y.npy", s["depth"][0].numpy().astype(np.float32))
        if track == "paper":
            np.save(OUT / f"{rec.name}_gt.npy", s["gt"][0].numpy().astype(np.float32))
            np.save(OUT / f"{rec.name}_m.npy", s["mask"][0].numpy().astype(np.float32))
            np.save(OUT / f"{rec.name}_rgb.npy", (s["rgb"].permute(1, 2, 0).numpy() * 255).astype(np.float32))
        print(track, rec.year if hasattr(rec, "year") else "", rec.name, flush=True)
