import os
OUT = os.environ.get("RGF_CHECK_DIR", "/tmp/rgf-check") + "/"
import numpy as np, torch
from torch_depth_sr.baselines import rolling_guidance_filter
for name in ("Art", "Teddy", "Baby1"):
    y = np.load(f"{OUT}{name}_y.npy"); gt = np.load(f"{OUT}{name}_gt.npy"); m = np.load(f"{OUT}{name}_m.npy") > 0
    r = lambda p: float(np.sqrt(((p - gt)[m] ** 2).mean()))
    yt = torch.from_numpy(y)[None, None]
    tel = torch.from_numpy(np.load(f"{OUT}{name}_telea.npy"))[None, None]
    for (ss, sc, it) in [(5, 7, 3), (3, 5, 4)]:
        o = np.load(f"{OUT}{name}_ocv_{ss}_{sc}_{it}.npy")
        ours = rolling_guidance_filter(yt, (yt > 0).float(), ss, sc, it)[0, 0].numpy()
        ours_it1 = rolling_guidance_filter(yt, (yt > 0).float(), ss, sc, max(1, it - 1))[0, 0].numpy()
        ours_tel = rolling_guidance_filter(tel, torch.ones_like(tel), ss, sc, max(1, it - 1))[0, 0].numpy()
        print(name, (ss, sc, it), "opencv %.3f ours %.3f ours(it-1) %.3f ours(telea,it-1) %.3f  max|ocv-ours(telea,it-1)| %.2f" % (r(o), r(ours), r(ours_it1), r(ours_tel), np.abs(o - ours_tel).max()))
