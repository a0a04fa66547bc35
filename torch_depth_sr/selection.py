"""Order statistics (the k-th smallest value, the lower median, the distinct values) of CPU tensors by numpy.

``torch.median`` and ``torch.kthvalue`` select on the CPU about five times slower than ``numpy.partition``
(640×480 values: 19.5 against 3.6 ms), and ``torch.unique`` sorts about five times slower than ``numpy.unique``
(420k float64 values: 81 against 16 ms); the scale policy and a stream's change test select over whole frames on
every forward, and the quantisation test takes the distinct values of up to 0.28 of a frame's. Each result is made
of elements of the input, so the values are the same bit for bit.

``numpy.partition`` itself slows down tenfold on values with many ties (640×480×3 colour changes of which nine in ten
are exactly 0, as between two frames of a still camera: 14 against 0.9 ms), so :func:`lower_median` first brackets
the median between two order statistics of a sample and selects among the values between them only
(:func:`_select_rows`; 0.3 ms there). Other devices (the device path, :func:`~torch_depth_sr.native.host_path`),
inputs that carry gradients and inputs with NaN (where torch returns NaN and numpy would sort it last) take torch's
path.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import torch

from .native import host_path

__all__ = ["distinct", "kth_smallest", "lower_median"]


def _host_values(v: torch.Tensor):
    """``v`` as a numpy array when numpy may select in it (the host path, no gradient, no NaN), else None."""
    if not host_path(v.device) or v.requires_grad or v.dtype not in (torch.float32, torch.float64):
        return None
    a = v.numpy()
    return None if np.isnan(a).any() else a


def kth_smallest(v: torch.Tensor, ks: Sequence[int]) -> torch.Tensor:
    """The values at the 0-based positions ``ks`` of the sorted 1-D ``v`` (``len(ks),``): ``v.kthvalue(k + 1)``
    for each ``k``, in one selection."""
    a = _host_values(v)
    if a is None:
        return torch.stack([v.kthvalue(k + 1).values for k in ks])
    return torch.from_numpy(np.partition(a, list(ks))[list(ks)])


def lower_median(v: torch.Tensor, dim: int = -1) -> torch.Tensor:
    """``v.median(dim).values``: the lower of the two middle values along ``dim`` (any shape)."""
    k = (v.shape[dim] - 1) // 2
    a = _host_values(v)
    if a is None or v.shape[dim] == 0:
        return v.median(dim).values
    if a.shape[dim] >= _BRACKETED:
        rows = np.moveaxis(a, dim, -1)
        return torch.from_numpy(_select_rows(rows.reshape(-1, rows.shape[-1]), k).reshape(rows.shape[:-1]))
    return torch.from_numpy(np.asarray(np.take(np.partition(a, k, axis=dim), k, axis=dim)))


_BRACKETED = 8192  # the rows from which _select_rows brackets the k-th value with a sample first
_SAMPLE = 4096  # about this many values of a row are sampled


def _select_rows(rows: np.ndarray, k: int) -> np.ndarray:
    """The k-th smallest value (0-based) of each row of ``rows (R,N)`` (no NaN): ``lo`` and ``hi``, the sample's order
    statistics about 3 standard errors either side of the k-th, bracket it in almost every row; then it is ``lo``
    itself when they are equal (ties), else the right one of the values between them. A row where the bracket misses
    selects in the whole row. Always the k-th value of the row, as ``numpy.partition`` gives it."""
    n = rows.shape[1]
    out = np.empty(rows.shape[0], rows.dtype)
    step = max(1, n // _SAMPLE)
    for i, row in enumerate(rows):
        sample = np.sort(row[::step])
        m = len(sample)
        at, reach = k * m / n, 1.5 * m**0.5 + 2
        lo, hi = sample[max(0, int(at - reach))], sample[min(m - 1, int(at + reach))]
        below = np.count_nonzero(row < lo)
        if lo == hi:
            if below <= k < below + np.count_nonzero(row == lo):
                out[i] = lo
                continue
        else:
            between = row[(row >= lo) & (row <= hi)]
            if below <= k < below + len(between):
                out[i] = np.partition(between, k - below)[k - below]
                continue
        out[i] = np.partition(row, k)[k]
    return out


def distinct(v: torch.Tensor) -> torch.Tensor:
    """``torch.unique(v)``: the distinct values of ``v``, sorted ascending (1-D)."""
    a = _host_values(v)
    if a is None:
        return torch.unique(v)
    return torch.from_numpy(np.unique(a))
