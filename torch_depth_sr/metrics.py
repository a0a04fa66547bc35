"""Error metrics over a mask, per sample: RMSE, MAE, bad-pixel rate, and the region breakdown of the tracks.

All take ``pred``, ``gt`` and ``mask`` shaped ``(B,1,H,W)`` (or ``(1,H,W)``/``(H,W)``) and return ``(B,)``
float64 tensors; a sample with an empty mask gives NaN.
"""
from __future__ import annotations

import torch


def _bhw(x: torch.Tensor) -> torch.Tensor:
    x = torch.as_tensor(x)
    while x.ndim < 4:
        x = x[None]
    return x.double()


def _masked_mean(v: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    m = (mask > 0).double()
    n = m.flatten(1).sum(1)
    s = (v * m).flatten(1).sum(1)
    return torch.where(n > 0, s / n.clamp_min(1), torch.full_like(s, float("nan")))


def rmse(pred, gt, mask) -> torch.Tensor:
    """Root mean squared error over ``mask`` per sample: sqrt(mean_mask (pred − gt)²)."""
    p, g, m = _bhw(pred), _bhw(gt).to(_bhw(pred)), _bhw(mask)
    return _masked_mean((p - g) ** 2, m).sqrt()


def mae(pred, gt, mask) -> torch.Tensor:
    """Mean absolute error over ``mask`` per sample."""
    p, g, m = _bhw(pred), _bhw(gt), _bhw(mask)
    return _masked_mean((p - g).abs(), m)


def bad_pixel_rate(pred, gt, mask, threshold: float) -> torch.Tensor:
    """Share of mask pixels with |pred − gt| > threshold (e.g. 1 disparity px = the file's scale factor)."""
    p, g, m = _bhw(pred), _bhw(gt), _bhw(mask)
    return _masked_mean(((p - g).abs() > threshold).double(), m)


def evaluate(pred: torch.Tensor, sample: dict) -> dict:
    """The metrics of tracks ``paper``/``sensor`` for one sample dict (benchmark.md).

    Uses ``gt``, ``mask`` (GT known), ``scale`` (grey levels per disparity px, for the bad-pixel
    threshold) and, when present, the region masks ``holes``, ``edges``, ``flying``, ``impulse``.
    Returns floats: rmse, mae, bad, rmse_holes, mae_holes, bad_holes, rmse_edges, mae_edges, bad_edges and
    flying_left (share of flying + impulse pixels left more than 3 grey levels off the GT).
    """
    gt, mask = sample["gt"], sample["mask"]
    thr = float(sample.get("scale", 1.0) or 1.0)
    p = _bhw(pred)[:1]
    out = {"rmse": float(rmse(p, gt, mask)[0]), "mae": float(mae(p, gt, mask)[0]),
           "bad": float(bad_pixel_rate(p, gt, mask, thr)[0])}
    for region, key in (("holes", "holes"), ("edges", "edges")):
        if region in sample:
            m = _bhw(sample[region]) * _bhw(mask)
            out[f"rmse_{key}"] = float(rmse(p, gt, m)[0])
            out[f"mae_{key}"] = float(mae(p, gt, m)[0])
            out[f"bad_{key}"] = float(bad_pixel_rate(p, gt, m, thr)[0])
    if "flying" in sample or "impulse" in sample:
        m = torch.zeros_like(_bhw(mask))
        for k in ("flying", "impulse"):
            if k in sample:
                m = torch.maximum(m, _bhw(sample[k]))
        m = m * _bhw(mask)
        if float(m.sum()) > 0:
            out["flying_left"] = float(bad_pixel_rate(p, gt, m, 3.0)[0])
    return out


__all__ = ["bad_pixel_rate", "evaluate", "mae", "rmse"]
