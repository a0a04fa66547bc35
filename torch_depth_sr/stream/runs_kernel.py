"""The two per-pixel updates of a stream's runs (:mod:`~torch_depth_sr.stream.runs`) as numba kernels.

Each pixel is read once and every map written once, where torch makes a temporary per operation. The arithmetic is
the torch path's: the same operations of the frame's dtype in the same order, the constants rounded to that dtype
first (as torch rounds a Python number against a tensor), so the values are the same bit for bit (tested). Rows split
across threads (:func:`~torch_depth_sr.native.run_range`). Compiled by LLVM at first use and cached on disk
(``cache=True``).
"""
from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit

from ..config import StreamConfig
from ..native import run_range

__all__ = ["grow_runs_cpu", "join_runs_cpu"]

_MIN_ROWS = 16  # rows per task below which one thread does them


@njit(cache=True, nogil=True, error_model="numpy")
def _join(t0, t1, y, observed, static, candidate, noise, evidence, mean, departed, age, offset, scale, c,
          y_out, observed_out, outlier_out, held_out, averaged_out, restarted_out, weight_out, departed_out,
          fresh_out):
    """Rows ``[t0, t1)`` of the ``B·H`` rows: :func:`~torch_depth_sr.stream.runs.join_runs`. ``c``: outlier_test
    (inf: none), fill_evidence, unmeasured_frames, weight, the settled age (``StreamConfig.settled_age``), 0, 1 in the
    dtype."""
    h, w = y.shape[1], y.shape[2]
    limit_k, fill_ev, unmeasured_cap, weight_k, settled, zero, one = c[0], c[1], c[2], c[3], c[4], c[5], c[6]
    for t in range(t0, t1):
        b = t // h
        i = t - b * h
        o, sc = offset[b], scale[b]
        for j in range(w):
            yv, ob, ev, st = y[b, i, j], observed[b, i, j], evidence[b, i, j], static[b, i, j]
            m_raw, dep, ag = mean[b, i, j], departed[b, i, j], age[b, i, j]
            had = m_raw > 0 and ev > 0
            mn = (m_raw - o) / sc
            limit = limit_k * noise[b, i, j]
            pending = (dep - o) / sc
            confirmed = dep > 0 and ob > 0 and abs(yv - pending) <= limit
            outlier = candidate[b, i, j] and ev >= fill_ev and not confirmed
            dropped = zero
            if outlier:
                dropped = yv * sc + o
                ob = zero
                yv = zero
            leaving = st and ob > 0 and had and abs(yv - mn) > limit
            held = leaving and not confirmed and ev >= fill_ev
            departed_out[b, i, j] = yv * sc + o if held else dropped
            if held:
                yv = mn
            measured = ob > 0
            restarted = leaving and not held
            averaged = st and measured and had and not restarted
            if averaged:
                yv = (yv + ev * mn) / (ev + one)
            aged = min(ag, unmeasured_cap) if (not measured and ev < fill_ev) else ag
            weight_out[b, i, j] = weight_k * aged if (st and not restarted) else zero
            y_out[b, i, j] = yv
            observed_out[b, i, j] = ob
            outlier_out[b, i, j] = outlier
            held_out[b, i, j] = held
            averaged_out[b, i, j] = averaged
            restarted_out[b, i, j] = restarted
            fresh_out[b, i, j] = (not st) or ag + one < settled


def _planes(*tensors: torch.Tensor) -> list:
    return [np.ascontiguousarray(t.detach().reshape(t.shape[0], t.shape[-2], t.shape[-1]).numpy()) for t in tensors]


def join_runs_cpu(y: torch.Tensor, observed: torch.Tensor, static: torch.Tensor, candidate: torch.Tensor,
                  noise: torch.Tensor, evidence: torch.Tensor, mean: torch.Tensor, departed: torch.Tensor,
                  age: torch.Tensor, offset: torch.Tensor, scale: torch.Tensor, s: StreamConfig) -> tuple:
    """:func:`~torch_depth_sr.stream.runs.join_runs`' maps for (B,1,H,W) CPU tensors of one float dtype (``static``,
    ``candidate`` bool; ``offset``, ``scale`` (B,)), no gradient: the fields of ``JoinedRuns`` in order."""
    b, _, h, w = y.shape
    arrays = _planes(y, observed, static, candidate, noise, evidence, mean, departed, age)
    dtype = arrays[0].dtype
    o = np.ascontiguousarray(offset.detach().numpy(), dtype=dtype)
    sc = np.ascontiguousarray(scale.detach().numpy(), dtype=dtype)
    c = np.array([s.outlier_test if s.outlier_test else math.inf, s.fill_evidence, s.unmeasured_frames, s.weight,
                  s.settled_age(), 0.0, 1.0], dtype=dtype)
    floats = [np.empty((b, h, w), dtype=dtype) for _ in range(3)]  # y, observed, weight
    flags = [np.empty((b, h, w), dtype=np.bool_) for _ in range(4)]  # outlier, held out, averaged, restarted
    departed_out, fresh = np.empty((b, h, w), dtype=dtype), np.empty((b, h, w), dtype=np.bool_)
    run_range(_join, b * h, *arrays, o, sc, c, floats[0], floats[1], *flags, floats[2], departed_out, fresh,
              min_share=_MIN_ROWS)

    def out(a):
        return torch.from_numpy(a).view(b, 1, h, w)

    return (out(floats[0]), out(floats[1]), *(out(f) for f in flags), out(floats[2]), out(departed_out), out(fresh))


@njit(cache=True, nogil=True, error_model="numpy")
def _grow(t0, t1, y, observed, trusted, confidence, static, restarted, evidence, age, past_confidence, past_mean,
          offset, scale, c, age_out, evidence_out, confidence_out, mean_out, counts):
    """Rows ``[t0, t1)`` of the ``B·H`` rows: :func:`~torch_depth_sr.stream.runs.grow_runs`. ``c``: max_frames,
    hole_decay, fill_evidence, 0, 1 in the dtype. ``counts[t]``: the row's holes filled from the past and static
    pixels."""
    h, w = y.shape[1], y.shape[2]
    max_frames, decay, fill_ev, zero, one = c[0], c[1], c[2], c[3], c[4]
    for t in range(t0, t1):
        b = t // h
        i = t - b * h
        o, sc = offset[b], scale[b]
        filled, still = 0, 0
        for j in range(w):
            ob, st, ev = observed[b, i, j], static[b, i, j], evidence[b, i, j]
            measured = ob > 0
            tr = trusted[b, i, j]
            age_out[b, i, j] = min(age[b, i, j] + one, max_frames) if st else one
            if st and not restarted[b, i, j]:
                grown = min(ev + one, max_frames)
                evidence_out[b, i, j] = grown if tr else (ev if measured else ev * decay)
            else:
                evidence_out[b, i, j] = one if tr else zero
            if measured:
                confidence_out[b, i, j] = confidence[b, i, j]
                mean_out[b, i, j] = y[b, i, j] * sc + o
            elif st:
                confidence_out[b, i, j] = past_confidence[b, i, j] * decay
                mean_out[b, i, j] = past_mean[b, i, j]
            else:
                confidence_out[b, i, j] = zero
                mean_out[b, i, j] = zero
            if st:
                still += 1
                if not measured and ev >= fill_ev:
                    filled += 1
        counts[t, 0] = filled
        counts[t, 1] = still


def grow_runs_cpu(y: torch.Tensor, observed: torch.Tensor, trusted: torch.Tensor, confidence: torch.Tensor,
                  static: torch.Tensor, restarted: torch.Tensor, evidence: torch.Tensor, age: torch.Tensor,
                  past_confidence: torch.Tensor, past_mean: torch.Tensor, offset: torch.Tensor, scale: torch.Tensor,
                  s: StreamConfig) -> tuple:
    """:func:`~torch_depth_sr.stream.runs.grow_runs` for (B,1,H,W) CPU tensors of one float dtype (``trusted``,
    ``static``, ``restarted`` bool; ``offset``, ``scale`` (B,)), no gradient: ``(age, evidence, confidence, mean,
    filled from the past, static)``, the last two as shares of the pixels."""
    b, _, h, w = y.shape
    arrays = _planes(y, observed, trusted, confidence, static, restarted, evidence, age, past_confidence, past_mean)
    dtype = arrays[0].dtype
    o = np.ascontiguousarray(offset.detach().numpy(), dtype=dtype)
    sc = np.ascontiguousarray(scale.detach().numpy(), dtype=dtype)
    c = np.array([s.max_frames, s.hole_decay, s.fill_evidence, 0.0, 1.0], dtype=dtype)
    outs = [np.empty((b, h, w), dtype=dtype) for _ in range(4)]
    counts = np.zeros((b * h, 2), dtype=np.int64)
    run_range(_grow, b * h, *arrays, o, sc, c, *outs, counts, min_share=_MIN_ROWS)
    n = b * h * w
    filled, still = counts.sum(0)
    return (*(torch.from_numpy(a).view(b, 1, h, w) for a in outs), float(filled) / n, float(still) / n)
