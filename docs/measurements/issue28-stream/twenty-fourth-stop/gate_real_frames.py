"""Issue 28, twenty-fourth stop: does the per-frame singular gate's dilution at camera resolution matter on real frames?

The gate (``stages._gate``) calls a sample clean when fewer than 0.2 % of its measured pixels are gross failures of the
singular test; the twenty-third stop found that a 640×480 frame can fall below it with a mover's flying pixels in it.
Here, on real 640×480 and 640×360 sensor frames (two of each real sequence, the TUM and SUN samples), each gated test's
share of gross failures, and how far the output moves when the gate's verdict is forced to "not clean" (the edge steps
on, the test's own Q): pixels moved by more than 1 % and 5 % of their depth.

    OMP_NUM_THREADS=2 python docs/measurements/issue28-stream/twenty-fourth-stop/gate_real_frames.py
"""
from __future__ import annotations

import math

import cv2
import numpy as np
import torch

import torch_depth_sr.stages as stages
from torch_depth_sr import DepthRestorer, restore_depth
from torch_depth_sr._data_root import data_root

SHARES: list = []
GATE = stages._gate


def logged_gate(obs, q, conf, c):
    ob = obs.observed.flatten(1)
    gross = (conf.flatten(1) < math.exp(-2.0)).to(ob.dtype) * ob
    SHARES.append(float(gross.sum() / ob.sum()))
    return GATE(obs, q, conf, c)


def never_clean(obs, q, conf, c):
    return q, torch.zeros(q.shape[0], 1, 1, 1, dtype=torch.bool, device=q.device)


def _moved_pixels(depth: np.ndarray, gated: np.ndarray, forced: np.ndarray, moved: np.ndarray) -> tuple[int, int]:
    """Of the ``moved`` pixels: how many are flying-like (the raw value more than a tenth of the way from both ends of
    its 5×5 window's measured range, a range over 5 % of the value), and at how many the forced output lies nearer one
    end of that range than the gated output does (a flying pixel sent to a side)."""
    padded = np.pad(np.where(depth > 0, depth, np.nan), 2, constant_values=np.nan)
    ys, xs = np.nonzero(moved)
    if len(ys) == 0:
        return 0, 0
    windows = np.stack([padded[y:y + 5, x:x + 5] for y, x in zip(ys, xs)])
    lo, hi = np.nanmin(windows, (1, 2)), np.nanmax(windows, (1, 2))
    v, span = depth[ys, xs], hi - lo
    flying = ((v - lo) > 0.1 * span) & ((hi - v) > 0.1 * span) & (span > 0.05 * v)

    def to_side(out):
        return np.minimum(np.abs(out[ys, xs] - lo), np.abs(out[ys, xs] - hi))

    return int(flying.sum()), int((to_side(forced) < to_side(gated)).sum())


def use(model: DepthRestorer, gate) -> None:
    """``gate`` in every singular detector of ``model`` (each holds the gate it was built with)."""
    for m in model.modules():
        if isinstance(m, stages.SingularDetector):
            m._gate = gate


def frames(root) -> list:
    seq, o3d = root / "real_sequences", root / "real_sensor_samples_open3d"
    out = [(f"tabletop {i}", seq / f"realsense_static_tabletop/depth/{i:05d}.png",
            seq / f"realsense_static_tabletop/rgb/{i:05d}.jpg") for i in (0, 100)]
    out += [(f"desk {i}", seq / f"realsense_d435_t265_desk/depth/{i:06d}.png",
             seq / f"realsense_d435_t265_desk/rgb/{i:06d}.jpg") for i in (0, 75)]
    return out + [("TUM", o3d / "TUM/TUM_depth.png", o3d / "TUM/TUM_color.png"),
                  ("SUN", o3d / "SUN/SUN_depth.png", o3d / "SUN/SUN_color.jpg")]


def main() -> None:
    torch.set_num_threads(2)
    root = data_root()
    for name in ("denoise-fast", "denoise-default"):
        model = DepthRestorer.from_pretrained(name).eval()
        print(name)
        for label, d, c in frames(root):
            depth = cv2.imread(str(d), cv2.IMREAD_UNCHANGED).astype(np.float32)
            rgb = np.ascontiguousarray(cv2.imread(str(c))[..., ::-1])
            SHARES.clear()
            with torch.no_grad():
                use(model, logged_gate)
                gated = restore_depth(depth, rgb, model=model)
                shares = list(SHARES)
                use(model, never_clean)
                forced = restore_depth(depth, rgb, model=model)
            use(model, GATE)
            measured = depth > 0
            moved = np.abs(gated - forced) / np.maximum(depth, 1)
            clean = "clean" if shares[-1] < 0.002 else "not clean"
            flying, sided = _moved_pixels(depth, gated, forced, measured & (moved > 0.05))
            print(f"  {label:12s} {depth.shape[1]}x{depth.shape[0]} gross {min(shares):.3%}–{max(shares):.3%} ({clean})"
                  f"  forced not clean: {int((measured & (moved > 0.01)).sum())} px moved >1 %,"
                  f" {int((measured & (moved > 0.05)).sum())} >5 % (of {int(measured.sum())}):"
                  f" {flying} of them flying-like,"
                  f" {sided} nearer a side forced than gated")


if __name__ == "__main__":
    main()
