import os
OUT = os.environ.get("RGF_CHECK_DIR", "/tmp/rgf-check") + "/"
import numpy as np, torch
from torch_depth_sr._data_root import data_root
from torch_depth_sr.datasets.discover import find_scenes
from torch_depth_sr.evaluation.protocols import make_degradation
recs = {r.name: r for r in find_scenes(data_root(), "paper")}
for name in ("Art", "Teddy", "Baby1"):
    scene = recs[name].load()
    s = make_degradation("paper", seed=0)(scene) if True else None
    np.save(f"{OUT}{name}_y.npy", s["depth"][0].numpy().astype(np.float32))
    np.save(f"{OUT}{name}_gt.npy", scene["gt"][0].numpy().astype(np.float32))
    np.save(f"{OUT}{name}_m.npy", scene["mask"][0].numpy().astype(np.float32))
print("ok")
