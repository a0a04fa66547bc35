"""Write the `sensor` track's exact bench inputs (21 scenes) as .npy for the OpenCV weighted-median check.

Same generator as ``torch-depth-sr bench --track sensor`` (``bench._samples``: same seeds, inputs below 0
clamped to 0 = missing). Files in $WMF_CHECK_DIR (default /tmp/wmf-check): <scene>_y.npy (input depth),
<scene>_gt.npy, <scene>_known.npy (GT-known mask), <scene>_out.npy (flying | impulse, as metrics.evaluate
builds it, & known), <scene>_rgb.npy (H,W,3 float32 on 0-255, RGB), <scene>_scale.npy.
"""
import os
from pathlib import Path

import numpy as np

from torch_depth_sr._data_root import data_root
from torch_depth_sr.evaluation.bench import _samples

OUT = Path(os.environ.get("WMF_CHECK_DIR", "/tmp/wmf-check"))
OUT.mkdir(parents=True, exist_ok=True)
for rec, s in _samples("sensor", data_root(), None, None):
    known = s["mask"][0].numpy() > 0.5 if "mask" in s else s["gt"][0].numpy() > 0
    outl = np.zeros_like(known)
    for k in ("flying", "impulse"):
        if k in s:
            outl |= s[k][0].numpy() > 0.5
    np.save(OUT / f"{rec.name}_y.npy", s["depth"][0].numpy().astype(np.float32))
    np.save(OUT / f"{rec.name}_gt.npy", s["gt"][0].numpy().astype(np.float32))
    np.save(OUT / f"{rec.name}_known.npy", known)
    np.save(OUT / f"{rec.name}_out.npy", outl & known)
    np.save(OUT / f"{rec.name}_rgb.npy", (s["rgb"].permute(1, 2, 0).numpy() * 255).astype(np.float32))
    np.save(OUT / f"{rec.name}_scale.npy", np.float32(s.get("scale", 1.0)))
    print(rec.name, int((outl & known).sum()), flush=True)
