import numpy as np
import torch

from torch_depth_sr.metrics import bad_pixel_rate, evaluate, mae, rmse


def test_against_numpy():
    g = torch.Generator().manual_seed(0)
    p, t = torch.rand(2, 1, 9, 7, generator=g) * 10, torch.rand(2, 1, 9, 7, generator=g) * 10
    m = (torch.rand(2, 1, 9, 7, generator=g) > 0.3).float()
    for b in range(2):
        sel = m[b].numpy() > 0
        e = (p[b].numpy() - t[b].numpy())[sel]
        assert np.isclose(float(rmse(p, t, m)[b]), np.sqrt((e**2).mean()))
        assert np.isclose(float(mae(p, t, m)[b]), np.abs(e).mean())
        assert np.isclose(float(bad_pixel_rate(p, t, m, 2.0)[b]), (np.abs(e) > 2).mean())


def test_empty_mask_is_nan():
    z = torch.zeros(1, 1, 3, 3)
    assert torch.isnan(rmse(z, z, z)).all()


def test_evaluate_regions():
    gt = torch.full((1, 8, 8), 10.0)
    pred = gt.clone()[None]
    pred[..., 0, 0] = 20.0
    holes = torch.zeros(1, 8, 8)
    holes[..., 0, 0] = 1
    r = evaluate(pred, {"gt": gt, "mask": torch.ones(1, 8, 8), "scale": 3.0, "holes": holes, "flying": holes})
    assert np.isclose(r["rmse_holes"], 10.0) and np.isclose(r["bad"], 1 / 64) and r["flying_left"] == 1.0
