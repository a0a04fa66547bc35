"""Issue 28, thirty-first stop: where, relative to the movers, the stream's trail excess lies at 480×640.

Each scene is restored by the stream and frame by frame; ``e_stream² − e_frame²`` is summed over the trail region (a
mover's pixels grown by 2 px and the pixels it left in the last four frames) in groups, divided by the region's
size (each row is that group's share of the difference of the two mean squared errors). The groups: where the pixel
lies relative to the movers (on a mover now, 3 px or more inside it or within 2 px of its edge; outside it within
2 px; or left by one 1, 2, 3 or 4 frames ago), crossed with the
stream's change test (static or changed) and the input (measured or a hole). Fitting scenes only: it reads ground
truth and the movers' masks to sort pixels, which the stream never does.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/thirty-first-stop/trail_lag.py --size 480x640 --seeds 303
    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/thirty-first-stop/trail_lag.py --seeds 400 401 402 403 \
        404 405 406 407 408 409 --recipe static-busy
"""
from __future__ import annotations

import argparse
from collections import defaultdict
from multiprocessing import Pool

import numpy as np
import torch

from torch_depth_sr import restore_depth
from torch_depth_sr.datasets.sequences import make_sequence, recipe_sequences
from torch_depth_sr.evaluation.stream import regions
from torch_depth_sr.stream import StreamRestorer, default_stream_model
from torch_depth_sr.window_max import dilate


PLACES = {-1: "other", 0: "ring outside a mover (2 px)", 5: "a mover's edge band (2 px in)",
          6: "a mover, 3+ px in", **{k: f"left {k} ago" for k in range(1, 5)}}


def _where(moving: np.ndarray, t: int) -> np.ndarray:
    """(H,W) int: on a mover now, 6 at least 3 px inside it, 5 within 2 px of its edge; 0 outside it within 2 px; k
    if a mover left the pixel k frames ago (1-4); else -1."""
    def grown(m, r):
        return dilate(torch.from_numpy(m)[None, None], r)[0, 0].numpy()

    now = moving[t]
    out = np.where(now, np.where(grown(~now, 2), 5, 6), np.where(grown(now, 2), 0, -1))
    for k in range(1, 5):
        if t - k >= 0:
            out = np.where((out < 0) & moving[t - k], k, out)
    return out


def trail_errors(seq: dict, stream: StreamRestorer, model):
    """Per frame with a trail region: ``(t, depth, step details, region, squared error of the stream, of frame by
    frame)``, the stream stepped on every frame (also ``shadow_fill.py``'s loop)."""
    trail = regions(seq)["trail"]
    gt = seq["gt"][:, 0].astype(np.float64)
    with torch.no_grad():
        for t in range(len(gt)):
            depth, rgb = seq["depth"][t].astype(np.float32), seq["rgb"][t]
            s = stream.step(depth, rgb, return_details=True)
            f = restore_depth(depth, rgb, model=model)
            region = trail[t]
            if not region.any():
                continue
            es = (np.nan_to_num(s.depth[0]) - gt[t]) ** 2
            ef = (np.nan_to_num(np.asarray(f)[0]) - gt[t]) ** 2
            yield t, depth, s, region, es, ef


def _scene(job):
    spec, size = job
    torch.set_num_threads(1)
    seq = make_sequence(spec, frames=30, height=size[0], width=size[1])
    moving = seq["moving"][:, 0].astype(bool)
    model = default_stream_model().eval()
    sums: dict = defaultdict(float)
    for t, depth, s, region, es, ef in trail_errors(seq, StreamRestorer(model), model):
        diff = es - ef
        where = _where(moving, t)
        static = s.static[0] > 0
        hole = depth[0] <= 0
        for k in PLACES:
            for cname, cm in (("static", static), ("changed", ~static)):
                for hname, hm in (("measured", ~hole), ("hole", hole)):
                    m = region & (where == k) & cm & hm
                    key = f"{PLACES[k]}, {cname}, {hname}"
                    sums[key] += diff[m].sum()
                    sums["n " + key] += m.sum()
        sums["pixels"] += region.sum()
        sums["stream"] += es[region].sum()
        sums["frame"] += ef[region].sum()
    n = sums.pop("pixels")
    return spec.name, n, sums


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", default="480x640")
    p.add_argument("--processes", type=int, default=2)
    p.add_argument("--seeds", type=int, nargs="+", default=[303], help="fitting seeds only (300-303, 400-409)")
    p.add_argument("--recipe", default=None, help="one recipe only (static-2movers, pan-then-hold, static-busy)")
    a = p.parse_args()
    size = tuple(int(t) for t in a.size.split("x"))
    specs = [s for s in recipe_sequences(a.seeds) if a.recipe in (None, s.name.split("@")[0])]
    with Pool(a.processes) as pool:
        results = pool.map(_scene, [(s, size) for s in specs], chunksize=1)
    shares: dict = defaultdict(float)  # each group's share of the MSE difference, summed over the scenes
    for name, n, sums in results:
        rs, rf = np.sqrt(sums.pop("stream") / n), np.sqrt(sums.pop("frame") / n)
        print(f"{name} at {a.size}: trail {rs:.2f} stream, {rf:.2f} frame by frame; MSE difference "
              f"{rs ** 2 - rf ** 2:+.2f}, by group (pixel-frames):")
        for k, v in sums.items():
            if not k.startswith("n ") and sums["n " + k]:
                print(f"  {k:48s} {v / n:+9.2f}   ({int(sums['n ' + k])})")
                shares[k] += v / n / len(results)
                shares["n " + k] += sums["n " + k]
    if len(results) > 1:
        print(f"mean over the {len(results)} scenes, by group (pixel-frames in all):")
        for k in sorted((k for k in shares if not k.startswith("n ")), key=shares.get):
            print(f"  {k:48s} {shares[k]:+9.2f}   ({int(shares['n ' + k])})")


if __name__ == "__main__":
    main()
