"""What the guidance network's maps look like: the λ/μ₁ (TV threshold) multipliers of a trained model on one scene.

    PYTHONPATH=. python docs/measurements/guidance/maps.py MODEL_FOLDER --track paper --scene Art \
        --out docs/measurements/guidance/lambda-Art.png

Writes a PNG mosaic (colour, input, output; the TV-threshold multiplier per direction and the nonlocal and outlier
multipliers of the first and the last layer, log scale from 1/R (blue) to R (red), 1 = white, R the model's
``guidance.range``, 4 unless set) and prints the percentiles of each log2-multiplier per layer and the share of
pixels within 5 % (in the log) of the cap as JSON.
"""
from __future__ import annotations

import argparse
import json
import math

import cv2
import numpy as np
import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.figures import depth_to_bgr, mosaic, rgb_to_bgr, write_png


def _log_map_to_bgr(log_m: np.ndarray, c: float) -> np.ndarray:
    """log multiplier in [-c, c] -> blue (1/R) .. white (1) .. red (R), R = exp(c)."""
    t = np.clip(log_m / c, -1, 1)
    r = np.where(t > 0, 1.0, 1.0 + t)
    b = np.where(t < 0, 1.0, 1.0 - t)
    g = 1.0 - np.abs(t)
    return (np.stack([b, g, r], -1) * 255).round().astype(np.uint8)


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("model", help="a saved model folder with a guidance network (e.g. runs/guided/best)")
    p.add_argument("--track", default="paper")
    p.add_argument("--scene", default="Art")
    p.add_argument("--data", default=None)
    p.add_argument("--out", default="docs/measurements/guidance/lambda.png")
    a = p.parse_args()
    torch.set_num_threads(1)
    from torch_depth_sr._data_root import data_root
    from torch_depth_sr.evaluation.bench import _samples

    (rec, sample), = list(_samples(a.track, a.data or data_root(), [a.scene], None))
    model = DepthRestorer.load(a.model)
    if model.guidance is None:
        raise SystemExit(f"{a.model} has no guidance network (its config's guidance is None)")
    raw = {}
    hooks = [h.register_forward_hook(lambda m, i, o, k=k: raw.__setitem__(k, o.detach()))
             for k, h in enumerate(model.guidance.heads)]
    y, rgb = sample["depth"][None], sample["rgb"][None]
    with torch.no_grad():
        out = model(y, rgb)
    for h in hooks:
        h.remove()
    c = model.guidance.max_log_multiplier
    logs = {k: c * torch.tanh(r)[0].numpy() for k, r in raw.items()}  # (5,H,W) per layer
    names = ["tv_h", "tv_v", "nl_h", "nl_v", "gamma"]
    stats = {f"layer{k}": {n: [round(float(v), 3) for v in np.percentile(l[i] / math.log(2), [5, 50, 95])]
                           for i, n in enumerate(names)} for k, l in logs.items()}
    at_cap = {f"layer{k}": {n: round(float((np.abs(l[i]) > 0.95 * c).mean()), 3) for i, n in enumerate(names)}
              for k, l in logs.items()}
    gt = sample["gt"][0]
    v = gt[gt > 0]
    lo, hi = float(v.quantile(0.005)), float(v.quantile(0.995))
    top = [rgb_to_bgr(rgb), depth_to_bgr(y, lo, hi), depth_to_bgr(out, lo, hi)]
    rows, labels = [top], [["colour", "input", "output"]]
    for k in (0, len(logs) - 1):
        l = logs[k]
        rows.append([_log_map_to_bgr(l[0], c), _log_map_to_bgr(l[1], c), _log_map_to_bgr(0.5 * (l[2] + l[3]), c)])
        labels.append([f"layer {k}: lambda x, horiz.", f"layer {k}: lambda x, vert.", f"layer {k}: eta x (mean)"])
    write_png(a.out, mosaic(rows, labels, max_width=360))
    print(json.dumps({"scene": rec.name, "track": a.track, "model": a.model,
                      "guidance_range": math.exp(c), "log2_multiplier_p5_p50_p95": stats,
                      "share_at_cap": at_cap}, indent=1))


if __name__ == "__main__":
    main()
