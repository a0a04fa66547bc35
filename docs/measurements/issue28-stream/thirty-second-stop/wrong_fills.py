"""Issue 28, thirty-second stop: with ``fill="trusted"``, how often the output shows a surface that is not there.

A *wrong* pixel is one the output gives a value (not left missing) that is off the ground truth by more than
``--tolerance`` of its depth (default 5 %): a surface where none is, or at the wrong depth. Counted per method over
each synthetic sequence's frames, split by the input (measured or a hole) and by the trail region near the movers
(``evaluation.stream.regions``) or elsewhere, as a share of all pixel-frames (per million). The stream and frame by
frame restore with ``fill="trusted"``: what a robot that reads only the confident output sees. The last column,
``holes filled``, counts the input's holes given a value (per million pixel-frames): leaving holes missing is how a
method avoids wrong fills.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/thirty-second-stop/wrong_fills.py --size 120x160 \
        --seeds 300 301 302 303
    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/thirty-second-stop/wrong_fills.py --size 480x640 \
        --recipe static-busy --no-tuning --seeds 404 --figure docs/stream/stream_wrong_fills.png
"""
from __future__ import annotations

import argparse
from multiprocessing import Pool

import numpy as np
import torch

from torch_depth_sr import restore_depth
from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, TUNING_SEQUENCES, make_sequence, recipe_sequences
from torch_depth_sr.evaluation.stream import regions
from torch_depth_sr.stream import StreamRestorer, default_stream_model

GROUPS = ("trail, hole", "trail, measured", "elsewhere, hole", "elsewhere, measured", "holes filled")


def _scene(job):
    spec, size, tolerance, settings = job
    torch.set_num_threads(1)
    seq = make_sequence(spec, frames=30, height=size[0], width=size[1])
    trail = regions(seq)["trail"]
    gt = seq["gt"][:, 0].astype(np.float64)
    model = default_stream_model().eval()
    stream = StreamRestorer(model, settings, fill="trusted")
    counts = {m: dict.fromkeys(GROUPS, 0) for m in ("frame", "stream")}
    with torch.no_grad():
        for t in range(len(gt)):
            depth, rgb = seq["depth"][t].astype(np.float32), seq["rgb"][t]
            outs = {"stream": np.asarray(stream.step(depth, rgb))[0],
                    "frame": np.asarray(restore_depth(depth, rgb, model=model, fill="trusted"))[0]}
            hole = depth[0] <= 0
            for method, out in outs.items():
                wrong = np.isfinite(out) & (out > 0) & (np.abs(out - gt[t]) > tolerance * gt[t])
                counts[method]["holes filled"] += int((hole & np.isfinite(out) & (out > 0)).sum())
                for g in GROUPS[:-1]:
                    where = (trail[t] if g.startswith("trail") else ~trail[t]) & (hole if g.endswith("hole") else ~hole)
                    counts[method][g] += int((wrong & where).sum())
    return spec.name, gt.size, counts


def figure(spec, size: tuple, frames: list, path: str) -> None:
    """A picture of ``frames`` of ``spec``: the colour, the input, frame by frame's and the stream's output with
    ``fill="trusted"`` (missing black, wrong pixels red) and the ground truth, a row per frame, and below each a
    quarter-size crop where the two methods' wrong pixels are densest."""
    import cv2
    from torch_depth_sr.figures import depth_to_bgr, mosaic, rgb_to_bgr, write_png

    seq = make_sequence(spec, frames=max(frames) + 1, height=size[0], width=size[1])
    gt = seq["gt"][:, 0].astype(np.float64)
    lo, hi = float(np.percentile(gt, 0.5)), float(np.percentile(gt, 99.5))
    model = default_stream_model().eval()
    stream = StreamRestorer(model, fill="trusted")
    rows, labels = [], []

    def marked(out, t):
        img = depth_to_bgr(out, lo, hi)
        img[np.isfinite(out) & (out > 0) & (np.abs(out - gt[t]) > 0.05 * gt[t])] = (0, 0, 255)
        return img
    with torch.no_grad():
        for t in range(max(frames) + 1):
            depth, rgb = seq["depth"][t].astype(np.float32), seq["rgb"][t]
            s = np.asarray(stream.step(depth, rgb))[0]
            if t in frames:
                f = np.asarray(restore_depth(depth, rgb, model=model, fill="trusted"))[0]
                panels = [rgb_to_bgr(rgb), depth_to_bgr(depth[0], lo, hi), marked(f, t), marked(s, t),
                          depth_to_bgr(gt[t], lo, hi)]
                rows.append(panels)
                labels.append([f"{spec.name} frame {t}", "input (holes black)", "frame by frame (wrong red)",
                               "stream (wrong red)", "ground truth"])
                h, w = size[0] // 4, size[1] // 4
                wrong = ((panels[2] == (0, 0, 255)).all(-1) | (panels[3] == (0, 0, 255)).all(-1)).astype(np.float32)
                density = cv2.boxFilter(wrong, -1, (w, h), normalize=False)
                cy, cx = np.unravel_index(np.argmax(density), density.shape)
                y0, x0 = int(np.clip(cy - h // 2, 0, size[0] - h)), int(np.clip(cx - w // 2, 0, size[1] - w))
                rows.append([p[y0:y0 + h, x0:x0 + w] for p in panels])
                labels.append([f"crop at ({y0}, {x0}), {h}x{w}"] + [""] * 4)
    print("figure:", write_png(path, mosaic(rows, labels, max_width=240)))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", default="120x160")
    p.add_argument("--processes", type=int, default=2)
    p.add_argument("--seeds", type=int, nargs="*", default=[300, 301, 302, 303],
                   help="recipe seeds (fitting: 300-303, 400-409); the tuning sequences are always included")
    p.add_argument("--recipe", default=None, help="only this recipe (static-2movers, pan-then-hold, static-busy)")
    p.add_argument("--no-tuning", action="store_true", help="leave the tuning sequences out")
    p.add_argument("--evaluated", action="store_true", help="the stream track's evaluated sequences instead (report)")
    p.add_argument("--tolerance", type=float, default=0.05)
    p.add_argument("--figure", default=None, help="a PNG of the first sequence's --figure-frames (no table)")
    p.add_argument("--figure-frames", type=int, nargs="+", default=[10, 20])
    p.add_argument("--settings", default="{}", help="StreamConfig overrides as a Python dict literal")
    a = p.parse_args()
    import ast
    settings = ast.literal_eval(a.settings)
    size = tuple(int(t) for t in a.size.split("x"))
    specs = [*([] if a.no_tuning else TUNING_SEQUENCES), *recipe_sequences(a.seeds)]
    if a.evaluated:
        specs = list(STREAM_SEQUENCES)
    specs = [s for s in specs if a.recipe is None or s.name.split("@")[0].removeprefix("tune-") == a.recipe]
    if a.figure:
        figure(specs[0], size, a.figure_frames, a.figure)
        return
    with Pool(a.processes) as pool:
        results = pool.map(_scene, [(s, size, a.tolerance, settings) for s in specs], chunksize=1)
    print(f"wrong pixels (off by more than {a.tolerance:.0%}, given a value) per million pixel-frames, {a.size}, "
          f"fill='trusted', stream settings {settings}")
    print(f"{'sequence':22s} {'method':7s} " + " ".join(f"{g:>20s}" for g in GROUPS))
    total = {m: dict.fromkeys(GROUPS, 0) for m in ("frame", "stream")}
    n_all = 0
    for name, n, counts in results:
        n_all += n
        for m, c in counts.items():
            print(f"{name:22s} {m:7s} " + " ".join(f"{1e6 * c[g] / n:20.1f}" for g in GROUPS))
            for g in GROUPS:
                total[m][g] += c[g]
    for m, c in total.items():
        print(f"{'all':22s} {m:7s} " + " ".join(f"{1e6 * c[g] / n_all:20.1f}" for g in GROUPS))


if __name__ == "__main__":
    main()
