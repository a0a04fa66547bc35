"""Metrics against plain numpy formulas."""

import math

import numpy as np
import pytest
import torch

from torch_depth_sr.errors import ShapeError
from torch_depth_sr.metrics import bad_pixel_rate, evaluate, geometric_mean, mae, rmse


def _data(seed=0, b=3, h=9, w=11):
    g = np.random.default_rng(seed)
    pred = g.normal(100, 10, (b, 1, h, w))
    gt = g.normal(100, 10, (b, 1, h, w))
    mask = (g.random((b, 1, h, w)) > 0.3).astype(np.float64)
    return pred, gt, mask


def test_against_numpy():
    pred, gt, mask = _data()
    r = rmse(torch.tensor(pred), torch.tensor(gt), torch.tensor(mask))
    m = mae(torch.tensor(pred), torch.tensor(gt), torch.tensor(mask))
    bad = bad_pixel_rate(torch.tensor(pred), torch.tensor(gt), torch.tensor(mask), threshold=3.0)
    assert r.shape == (3,)
    for i in range(3):
        sel = mask[i] > 0
        e = pred[i][sel] - gt[i][sel]
        assert math.isclose(float(r[i]), np.sqrt(np.mean(e**2)), rel_tol=1e-12)
        assert math.isclose(float(m[i]), np.mean(np.abs(e)), rel_tol=1e-12)
        assert math.isclose(float(bad[i]), np.mean(np.abs(e) > 3.0), rel_tol=1e-12)


def test_unbatched_no_mask_and_per_sample_threshold():
    pred, gt, _ = _data(b=2)
    p, g = torch.tensor(pred, dtype=torch.float32), torch.tensor(gt, dtype=torch.float32)
    assert rmse(p[0], g[0]).dim() == 0
    torch.testing.assert_close(rmse(p[0], g[0]), rmse(p, g)[0])
    thr = torch.tensor([1.0, 50.0])
    b = bad_pixel_rate(p, g, threshold=thr)
    assert float(b[1]) < float(b[0])


def test_empty_mask_nan_and_shape_errors():
    p = torch.ones(2, 1, 4, 4)
    m = torch.zeros(2, 1, 4, 4)
    m[0, 0, 0, 0] = 1
    r = rmse(p, p * 0, m)
    assert float(r[0]) == 1.0 and math.isnan(float(r[1]))
    with pytest.raises(ShapeError, match=r"pred must have the shape of gt \(1, 1, 4, 5\)"):
        rmse(torch.ones(1, 1, 4, 4), torch.ones(1, 1, 4, 5))


def test_nan_outside_mask_ignored():
    p = torch.tensor([[[[1.0, float("nan")]]]])
    g = torch.tensor([[[[0.0, 0.0]]]])
    assert float(rmse(p, g, torch.tensor([[[[1.0, 0.0]]]]))) == 1.0


def test_evaluate_regions():
    gt = torch.full((1, 6, 6), 100.0)
    gt[0, 0, 0] = 0.0
    pred = gt.clone()
    pred[0, 1, :] += 4.0  # row 1 off by 4 (> scale 3)
    holes = torch.zeros(1, 6, 6)
    holes[0, 1, :3] = 1
    holes[0, 0, 0] = 1
    flying = torch.zeros(1, 6, 6)
    flying[0, 1, 5] = 1
    flying[0, 2, 5] = 1
    s = {"gt": gt, "mask": (gt > 0).float(), "scale": 3.0, "holes": holes, "edges": torch.zeros(1, 6, 6),
         "flying": flying, "impulse": torch.zeros(1, 6, 6)}
    out = evaluate(pred, s)
    assert math.isclose(out["rmse"], math.sqrt(6 * 16 / 35))
    assert math.isclose(out["mae"], 6 * 4 / 35)
    assert math.isclose(out["bad"], 6 / 35)
    assert out["rmse_holes"] == 4.0 and out["bad_holes"] == 1.0
    assert math.isnan(out["rmse_edges"])
    assert out["flying_left"] == 0.5 and out["n_outliers"] == 2
    assert evaluate(pred[None], s)["rmse"] == out["rmse"]
    plain = evaluate(pred, {"gt": gt, "scale": 5.0})
    assert plain["bad"] == 0.0 and "rmse_holes" not in plain


def test_geometric_mean():
    assert math.isclose(geometric_mean([1.0, 4.0]), 2.0)
