"""Restore one noisy, holey depth map in one line (synthetic scene; no files needed).

    python examples/quickstart.py
"""
import torch

from torch_depth_sr import restore_depth
from torch_depth_sr.datasets.synthetic import make_scene

scene = make_scene(120, 160, seed=0)  # rgb (3,H,W) in [0,1], gt (1,H,W) disparity-like units
torch.manual_seed(0)
noisy = scene["gt"] + 5 * torch.randn_like(scene["gt"])
noisy[torch.rand_like(noisy) < 0.1] = 0  # 10 % missing pixels (0 = no measurement)

result = restore_depth(noisy.clamp_min(0), scene["rgb"], return_details=True)
valid = scene["mask"] > 0


def rmse(x):
    return float(((x - scene["gt"])[valid] ** 2).mean().sqrt())


print(f"noisy input RMSE (measured pixels): {float(((noisy - scene['gt'])[valid & (noisy > 0)] ** 2).mean().sqrt()):.2f}")
print(f"restored RMSE (all pixels):         {rmse(result.depth):.2f}")
print(f"estimated noise sigma: {result.info['noise_sigma'][0]:.2f}, CG iterations per layer: {result.info['cg_iterations']}")
print(f"share of measured pixels marked singular: {1 - float(result.trusted[noisy > 0].float().mean()):.4f}")
