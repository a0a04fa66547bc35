"""The default tier with its 16-channel refiner and with the 24-channel candidate, and kornia's 9x9 JBF, timed in turn
in one process at 640x480 (2 threads, five rounds, the median; a synthetic frame with noise sigma 3). A scratch
check over the two training runs' folders (runs/default-r16 (git show of the shipped denoise-default), runs/default-r24: the commands in docs/pretrained.md),
made after the speed track read the candidate over 25x; it decided nothing.

    python docs/measurements/issue27-tiers/twelfth-stop/time_r16_r24.py
"""
import time, torch, kornia
from torch_depth_sr import DepthRestorer
from torch_depth_sr.datasets.synthetic import make_scene
torch.set_num_threads(2)
s = make_scene(480, 640, seed=0)
d = (s["gt"] + 3 * torch.randn(s["gt"].shape, generator=torch.Generator().manual_seed(0)))[None].float()
rgb = s["rgb"][None].float()
models = {"r16": DepthRestorer.load("runs/default-r16").eval(), "r24": DepthRestorer.load("runs/default-r24/best").eval()}
def kjbf():
    return kornia.filters.joint_bilateral_blur(d, rgb, (9, 9), 0.1, (1.5, 1.5))
with torch.no_grad():
    for m in models.values(): m(d, rgb)
    kjbf()
    res = {k: [] for k in list(models) + ["kornia"]}
    for r in range(5):
        for k, m in models.items():
            t = time.perf_counter(); m(d, rgb); res[k].append(time.perf_counter() - t)
        t = time.perf_counter(); kjbf(); res["kornia"].append(time.perf_counter() - t)
for k, v in res.items():
    print(k, " ".join(f"{x:.3f}" for x in v), "median", f"{sorted(v)[2]:.3f}")
kn = sorted(res["kornia"])[2]
for k in models: print(k, f"{sorted(res[k])[2] / kn:.1f}x kornia")
