"""Seconds per stage and CG iterations per layer (with and without the DCT preconditioner).

    python examples/stage_timings.py [--sizes 463x370 640x480] [--threads 2]
"""
import argparse

import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.datasets.synthetic import make_scene

p = argparse.ArgumentParser()
p.add_argument("--sizes", nargs="*", default=["463x370", "640x480"])
p.add_argument("--threads", type=int, default=torch.get_num_threads())
args = p.parse_args()
torch.set_num_threads(args.threads)
print(f"threads={args.threads}")
for size in args.sizes:
    w, h = map(int, size.split("x"))
    s = make_scene(h, w, seed=0)
    g = torch.Generator().manual_seed(0)
    y = s["gt"][None] + 5 * torch.randn(s["gt"][None].shape, generator=g)
    y = torch.where(torch.rand(y.shape, generator=g) < 0.05, torch.zeros_like(y), y.clamp_min(1))
    rgb = s["rgb"][None]
    for precondition in (True, False):
        model = DepthRestorer(solver={"precondition": precondition})
        model(y, rgb)  # warm-up (compiles the C kernel on first use)
        info = model.restore_with_details(y, rgb, timings=True).info
        sec = info["seconds"]
        rest = sec["total"] - sum(v for k, v in sec.items() if k != "total")
        print(f"{size} precondition={precondition}: " + ", ".join(f"{k} {v:.3f}s" for k, v in sec.items())
              + f", rest {rest:.3f}s; CG iterations per layer {info['cg_iterations']}")
