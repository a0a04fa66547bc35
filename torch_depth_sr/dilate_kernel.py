"""The dilation of a bool mask (:func:`~torch_depth_sr.window_max.dilate`) as a numba kernel.

In torch a dilation is a float copy of the mask and a running maximum of ``2·radius`` shifted planes per axis, each a
temporary. Here it is a running count along each row, then one down the columns over the rows' verdicts: two passes
over the mask, on one thread (the thread pool's hand-over cost more than the work at 640×480: 0.3 ms at 463×370,
2.4 ms at 1376×1088, ``docs/measurements/issue28-stream/thirtieth-stop/``). The same mask as torch's (tested).
Compiled by LLVM at first use and cached on disk (``cache=True``).
"""
from __future__ import annotations

import numpy as np
import torch
from numba import njit

__all__ = ["dilate_cpu", "dilate_planes"]


@njit(cache=True, nogil=True)
def dilate_planes(planes, radius, out):
    """``out (P,H,W)`` bool: a set pixel of ``planes (P,H,W)`` uint8 within ``radius`` px (a square clipped to the
    image)."""
    n, h, w = planes.shape
    rows = np.empty((h, w), dtype=np.uint8)
    count = np.empty(w, dtype=np.int32)
    for p in range(n):
        for i in range(h):
            c = 0
            for j in range(min(radius, w)):
                c += planes[p, i, j]
            for j in range(w):
                if j + radius < w:
                    c += planes[p, i, j + radius]
                if j > radius:
                    c -= planes[p, i, j - radius - 1]
                rows[i, j] = c > 0
        count[:] = 0
        for i in range(min(radius, h)):
            for j in range(w):
                count[j] += rows[i, j]
        for i in range(h):
            if i + radius < h:
                for j in range(w):
                    count[j] += rows[i + radius, j]
            if i > radius:
                for j in range(w):
                    count[j] -= rows[i - radius - 1, j]
            for j in range(w):
                out[p, i, j] = count[j] > 0


def dilate_cpu(mask: torch.Tensor, radius: int) -> torch.Tensor:
    """``dilate(mask, radius)`` of a (B,C,H,W) bool mask on the CPU: grown by a square of ``radius`` px."""
    h, w = mask.shape[-2:]
    planes = np.ascontiguousarray(mask.detach().reshape(-1, h, w).numpy()).view(np.uint8)
    out = np.empty(planes.shape, dtype=np.bool_)
    dilate_planes(planes, int(radius), out)
    return torch.from_numpy(out).view(mask.shape)
