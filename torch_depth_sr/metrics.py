"""Error metrics of the benchmark (``shared/docs/benchmark.md``), per sample.

All functions take ``pred`` and ``gt`` of shape ``(B,1,H,W)`` (or ``(1,H,W)`` / ``(H,W)``,
treated as one sample) and an optional ``mask`` of the same shape (1 = evaluate; default: all
pixels). They return a ``(B,)`` tensor (a 0-dim tensor for unbatched input), computed in float64;
a sample whose mask is empty gives ``nan``.

* ``rmse = sqrt(Σ m (p − g)² / Σ m)``
* ``mae = Σ m |p − g| / Σ m``
* ``bad_pixel_rate(threshold) = Σ m [|p − g| > threshold] / Σ m``
"""

from __future__ import annotations

import math
from typing import Dict, Optional, Sequence, Union

import numpy as np
import torch

from torch_depth_sr._checks import check_same_shape
from torch_depth_sr.errors import DepthSRError, ShapeError

ArrayLike = Union[torch.Tensor, np.ndarray]  # anything torch.as_tensor takes as a depth map or mask


def _prepare(pred, gt, mask):
    pred, gt = torch.as_tensor(pred), torch.as_tensor(gt)
    check_same_shape(pred, gt, "pred", "gt")
    unbatched = pred.dim() < 4
    if pred.dim() == 2:
        pred, gt = pred[None, None], gt[None, None]
    elif pred.dim() == 3:
        pred, gt = pred[None], gt[None]
    elif pred.dim() != 4:
        raise ShapeError(f"pred must be (B,1,H,W), (1,H,W) or (H,W), got {tuple(pred.shape)}",
                         actual=tuple(pred.shape), expected="(B,1,H,W), (1,H,W) or (H,W)")
    if mask is None:
        m = torch.ones_like(gt, dtype=torch.float64)
    else:
        m = torch.as_tensor(mask, device=gt.device)
        m = m.reshape(gt.shape) if m.numel() == gt.numel() else m
        check_same_shape(m, gt, "mask", "gt")
        m = (m > 0.5).to(torch.float64) if m.dtype != torch.bool else m.to(torch.float64)
    err = pred.to(torch.float64) - gt.to(torch.float64)
    err = torch.where(m > 0, err, torch.zeros_like(err))  # ignore nan/inf outside the mask
    return err, m, unbatched


def _reduce(values, m, unbatched):
    num = (values * m).flatten(1).sum(1)  # (B,)
    den = m.flatten(1).sum(1)  # (B,)
    out = torch.where(den > 0, num / den.clamp_min(1.0), torch.full_like(num, float("nan")))
    return out[0] if unbatched else out


def rmse(pred: ArrayLike, gt: ArrayLike, mask: Optional[ArrayLike] = None) -> torch.Tensor:
    """Root-mean-square error over ``mask`` per sample."""
    err, m, ub = _prepare(pred, gt, mask)
    return _reduce(err * err, m, ub).sqrt()


def mae(pred: ArrayLike, gt: ArrayLike, mask: Optional[ArrayLike] = None) -> torch.Tensor:
    """Mean absolute error over ``mask`` per sample."""
    err, m, ub = _prepare(pred, gt, mask)
    return _reduce(err.abs(), m, ub)


def bad_pixel_rate(pred: ArrayLike, gt: ArrayLike, mask: Optional[ArrayLike] = None,
                   threshold: Union[float, torch.Tensor] = 1.0) -> torch.Tensor:
    """Share of masked pixels with ``|pred − gt| > threshold`` (float or per-sample ``(B,)``)."""
    err, m, ub = _prepare(pred, gt, mask)
    thr = torch.as_tensor(threshold, dtype=torch.float64, device=err.device)
    if thr.dim() == 1:
        if thr.numel() != err.shape[0]:
            raise ShapeError(f"threshold has {thr.numel()} values for a batch of {err.shape[0]}",
                             actual=tuple(thr.shape), expected=f"a float or ({err.shape[0]},)")
        thr = thr.view(-1, 1, 1, 1)
    return _reduce((err.abs() > thr).to(torch.float64), m, ub)


def geometric_mean(values: Union[Sequence[float], ArrayLike]) -> float:
    """Geometric mean (the ``upsample-a`` summary of the 12 per-image RMSEs)."""
    v = torch.as_tensor(values, dtype=torch.float64).flatten()
    if v.numel() == 0 or bool((v <= 0).any()):
        raise DepthSRError(f"geometric_mean needs positive values, got {v.tolist()}")
    return float(torch.exp(torch.log(v).mean()))


def evaluate(pred: ArrayLike, sample: dict, outlier_threshold: float = 3.0) -> Dict[str, float]:
    """All metrics of one restored sample, in grey levels of the stored ground truth.

    Args:
        pred: restored depth ``(1,H,W)`` or ``(1,1,H,W)`` at the ground truth's size.
        sample: the sample dict (``gt``, ``mask``, ``scale``; optionally the region masks
            ``holes``, ``edges``, ``flying``, ``impulse`` of the degradations).
        outlier_threshold: flying/impulse pixels more than this off the GT count as "left".

    Returns:
        dict of floats: ``rmse``, ``mae``, ``bad`` (|err| > ``scale`` grey levels, i.e. > 1
        disparity pixel) over GT-known pixels; where region masks exist, ``rmse_holes``,
        ``mae_holes``, ``bad_holes``, ``rmse_edges``, ``mae_edges``, ``bad_edges`` (GT-known
        pixels of the region; nan if empty); where ``flying``/``impulse`` exist,
        ``flying_left`` = share of flying+impulse pixels left > ``outlier_threshold`` off
        (plus ``n_outliers``).
    """
    if "gt" not in sample:
        raise DepthSRError(f"evaluate needs sample['gt'] (keys: {sorted(sample)})")
    gt = torch.as_tensor(sample["gt"])
    pred = torch.as_tensor(pred).to(gt.device)
    if pred.dim() == 4 and pred.shape[0] == 1:
        pred = pred[0]
    check_same_shape(pred, gt, "pred", "sample['gt']")
    known = torch.as_tensor(sample["mask"]) > 0.5 if "mask" in sample else gt > 0
    thr = float(sample.get("scale", 1.0))
    out: Dict[str, float] = {
        "rmse": float(rmse(pred, gt, known)),
        "mae": float(mae(pred, gt, known)),
        "bad": float(bad_pixel_rate(pred, gt, known, thr)),
    }
    for region, key in (("holes", "holes"), ("edges", "edges")):
        if region in sample:
            m = known & (torch.as_tensor(sample[region]) > 0.5)
            out[f"rmse_{key}"] = float(rmse(pred, gt, m))
            out[f"mae_{key}"] = float(mae(pred, gt, m))
            out[f"bad_{key}"] = float(bad_pixel_rate(pred, gt, m, thr))
    if "flying" in sample or "impulse" in sample:
        m = torch.zeros_like(known)
        for region in ("flying", "impulse"):
            if region in sample:
                m = m | (torch.as_tensor(sample[region]) > 0.5)
        m = m & known
        n = int(m.sum())
        out["n_outliers"] = float(n)
        out["flying_left"] = float(bad_pixel_rate(pred, gt, m, outlier_threshold)) if n else math.nan
    return out


__all__ = ["bad_pixel_rate", "evaluate", "geometric_mean", "mae", "rmse"]
