"""Issue 28, thirty-second stop: the stream's error in the holes beside moving objects (stereo shadows), by recipe.

Each scene is restored by the stream (with a ``--variants`` patch of this process) and frame by frame. Printed per
scene: the trail (RMS error over the trail region, mm) of both, and the share of the difference of their mean squared
errors that lies in holes within 2 px outside a mover, split by the stream's change verdict (static / changed).
Reads ground truth and the movers' masks to sort pixels, which the stream never does.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/thirty-second-stop/shadow_fill.py \
        --recipe static-busy --seeds 300 301 302 303 --variants shipped
"""
from __future__ import annotations

import argparse
import sys
from multiprocessing import Pool
from pathlib import Path

import numpy as np
import torch

from torch_depth_sr.datasets.sequences import make_sequence, recipe_sequences
from torch_depth_sr.stream import StreamRestorer, default_stream_model
from torch_depth_sr.window_max import dilate

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "thirty-first-stop"))
from trail_lag import trail_errors  # noqa: E402  (the thirty-first stop's per-frame loop)

# a variant: StreamConfig settings, or "holesR" (below)
SETTINGS = {"shipped": {}, "unmeasured0": {"unmeasured_frames": 0.0}, "unmeasured1": {"unmeasured_frames": 1.0}}
VARIANTS = [*SETTINGS, "holes4", "holes6", "holes8"]


def _patch(variant: str) -> None:
    """``holesR``: a hole within R px of a changed pixel is changed (it has no depth to test; a mover beside it may
    have left it), so it is not filled from the past."""
    if not variant.startswith("holes"):
        return
    import torch_depth_sr.stream.frame as frame

    radius, test = int(variant[5:]), frame.change_test

    def change_test(y, observed, *args, **kwargs):
        t = test(y, observed, *args, **kwargs)
        changed = t.changed | ((observed <= 0) & dilate(t.changed, radius))
        return t._replace(changed=changed, outlier=t.outlier & ~changed)
    frame.change_test = change_test


def _grown(m: np.ndarray, r: int) -> np.ndarray:
    return dilate(torch.from_numpy(m)[None, None], r)[0, 0].numpy()


def _scene(job):
    spec, size, variant = job
    torch.set_num_threads(1)
    _patch(variant)
    seq = make_sequence(spec, frames=30, height=size[0], width=size[1])
    moving = seq["moving"][:, 0].astype(bool)
    model = default_stream_model().eval()
    stream = StreamRestorer(model, SETTINGS.get(variant, {}))
    s_sum = f_sum = n = 0.0
    groups = {"shadow, static": 0.0, "shadow, changed": 0.0, "elsewhere": 0.0}
    for t, depth, s, region, es, ef in trail_errors(seq, stream, model):
        diff = (es - ef)
        ring = region & ~moving[t] & _grown(moving[t], 2) & (depth[0] <= 0)
        static = s.static[0] > 0
        groups["shadow, static"] += diff[ring & static].sum()
        groups["shadow, changed"] += diff[ring & ~static].sum()
        groups["elsewhere"] += diff[region & ~ring].sum()
        s_sum, f_sum, n = s_sum + es[region].sum(), f_sum + ef[region].sum(), n + region.sum()
    return spec.name, variant, np.sqrt(s_sum / n), np.sqrt(f_sum / n), {k: v / n for k, v in groups.items()}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", default="480x640")
    p.add_argument("--processes", type=int, default=2)
    p.add_argument("--recipe", default="static-busy")
    p.add_argument("--seeds", type=int, nargs="+", default=[300, 301, 302, 303])
    p.add_argument("--variants", nargs="+", default=["shipped"], choices=VARIANTS)
    a = p.parse_args()
    size = tuple(int(t) for t in a.size.split("x"))
    specs = [s for s in recipe_sequences(a.seeds) if s.name.split("@")[0] == a.recipe]
    jobs = [(s, size, v) for s in specs for v in a.variants]
    with Pool(a.processes) as pool:
        results = pool.map(_scene, jobs, chunksize=1)
    ratios: dict = {}
    for name, variant, rs, rf, g in results:
        ratios.setdefault(variant, []).append(rs / rf)
        print(f"{name:18s} {variant:10s} trail {rs:7.2f} stream {rf:7.2f} frame ({rs / rf:.3f}); MSE difference "
              + ", ".join(f"{k} {v:+.1f}" for k, v in g.items()), flush=True)
    for v, r in ratios.items():
        print(f"{v:10s} mean trail ratio {np.mean(r):.4f}, above 1: {int(np.sum(np.array(r) > 1))} of {len(r)}")


if __name__ == "__main__":
    main()
