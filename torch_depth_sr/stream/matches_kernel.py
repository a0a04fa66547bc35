"""The block matches of a crop (:func:`~torch_depth_sr.stream.matching.crop_matches`): a numba kernel.

The torch path divides every flat index of the crop by the frame's width, compares, and builds the crop's indices and
weights with ``torch.where``: ten passes with a temporary each over ``k`` planes of the crop, 8–10 ms a crop at
640×480 (``k`` = 16), twice per crop of a stream's later layers. This kernel reads each index once and writes the
crop's index (and with ``own`` the weight) once; integer arithmetic and copied weights, so the same values
(tested). Rows of the ``B·k`` planes split across threads (:func:`~torch_depth_sr.native.run_range`).
Compiled by LLVM at first use and cached on disk (``cache=True``).
"""
from __future__ import annotations

import numpy as np
import torch
from numba import njit

from ..native import run_range

__all__ = ["crop_matches_cpu"]

_MIN_ROWS = 64  # rows per task below which one thread does it


@njit(cache=True, nogil=True)
def _rows(t0, t1, index, weight, r0, c0, width, own, out_index, out_weight):
    """Rows ``[t0, t1)`` of the ``B·k·hc`` rows of the crop: each index moved to the crop's frame, or, outside the
    crop, the pixel's own index with no weight (``own``, which writes the weights) or -1."""
    k, hc, wc = out_index.shape[1], out_index.shape[2], out_index.shape[3]
    for t in range(t0, t1):
        plane = t // hc
        i = t - plane * hc
        b = plane // k
        m = plane - b * k
        for j in range(wc):
            v = index[b, m, r0 + i, c0 + j]
            y = v // width
            x = v - y * width - c0
            y = y - r0
            inside = 0 <= y < hc and 0 <= x < wc
            if inside:
                out_index[b, m, i, j] = y * wc + x
            else:
                out_index[b, m, i, j] = i * wc + j if own else -1
            if own:  # else the weights are the crop's as they are (a view, no copy)
                out_weight[b, m, i, j] = weight[b, m, r0 + i, c0 + j] if inside else 0.0


def crop_matches_cpu(index: torch.Tensor, weight: torch.Tensor, rows: slice, cols: slice, width: int,
                     own: bool) -> tuple[torch.Tensor, torch.Tensor]:
    """The crop ``(rows, cols)`` of the matches' ``index`` (B,k,H,W, int64, flat in a frame ``width`` wide) and
    ``weight`` (B,k,H,W float) on the CPU, as :func:`~torch_depth_sr.stream.matching.crop_matches` makes them."""
    b, k = index.shape[:2]
    hc, wc = rows.stop - rows.start, cols.stop - cols.start
    idx = index.detach().numpy()
    wts = weight.detach().numpy()
    out_index = np.empty((b, k, hc, wc), dtype=idx.dtype)
    out_weight = np.empty((b, k, hc, wc) if own else (1, 1, 1, 1), dtype=wts.dtype)
    run_range(_rows, b * k * hc, idx, wts, rows.start, cols.start, width, own, out_index, out_weight,
              min_share=_MIN_ROWS)
    return torch.from_numpy(out_index), torch.from_numpy(out_weight) if own else weight[..., rows, cols]
