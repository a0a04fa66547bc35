import pytest
import torch

torch.set_num_threads(2)


@pytest.fixture
def scene():
    """A small synthetic RGB-D scene with Gaussian noise and holes (8-bit disparity-like units)."""
    from torch_depth_sr.datasets.synthetic import make_scene

    s = make_scene(48, 64, seed=3)
    g = torch.Generator().manual_seed(0)
    gt = s["gt"][None]
    noisy = gt + 5 * torch.randn(gt.shape, generator=g)
    holes = torch.rand(gt.shape, generator=g) < 0.05
    noisy = torch.where(holes | (gt <= 0), torch.zeros_like(noisy), noisy.clamp_min(1.0))
    return {"depth": noisy, "rgb": s["rgb"][None], "gt": gt, "mask": s["mask"][None]}
