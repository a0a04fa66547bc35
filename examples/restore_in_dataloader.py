"""Clean depth inside a data pipeline: RestoreDepth per sample in DataLoader workers (CPU).

    python examples/restore_in_dataloader.py --workers 2 --frames 16 --size 240 320 --tier fast

``--tier`` picks the speed tier by name (``fast``, ``default`` or ``best``; ``DepthRestorer.from_preset``,
docs/speed.md); ``--pretrained NAME`` a shipped model instead (``DepthRestorer.from_pretrained``, e.g. ``denoise-fast``,
the fast tier until 2026-12-05). The main process loads the compiled kernels (numba) before the workers start
(``torch_depth_sr.warmup`` with the model: one forward on a small frame, float32, loads the kernels it calls and
compiles them on a fresh install): the workers, forked from it, start with them instead of each loading them again.

It prints two rates: over the whole run with the start-up (the warm-up, the workers' fork, the first frames), and the
steady rate of an epoch, from the batch by which every worker has delivered its first to the last.

On a GPU, restore after collation instead (batched):
    restore = RestoreDepth(preset="fast", device="cuda"); batch = restore({"depth": depth.cuda(), "rgb": rgb.cuda()})
"""
import argparse
import time

import torch
from torch.utils.data import DataLoader

from torch_depth_sr import DepthRestorer
from torch_depth_sr.datasets.synthetic import SyntheticScenes
from torch_depth_sr.degradations import SensorDegradation
from torch_depth_sr.transforms import Compose, RestoreDepth
from torch_depth_sr.warmup import warmup


class Degrade:
    """Sensor degradation (noise, holes, flying pixels) keeping only the keys we batch."""

    def __call__(self, s):
        s = SensorDegradation(seed=0)(s)
        return {k: s[k] for k in ("depth", "rgb", "gt", "mask", "name")}


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--frames", type=int, default=16)
    p.add_argument("--size", type=int, nargs=2, default=(240, 320))
    p.add_argument("--tier", default="fast", help="fast, default or best (or any DepthRestorer.from_preset name)")
    p.add_argument("--pretrained", default=None, help="a shipped model (from_pretrained) instead of the tier")
    p.add_argument("--layers", type=int, default=None, help="override the tier's number of layers")
    a = p.parse_args()
    overrides = {} if a.layers is None else {"num_layers": a.layers}
    if a.pretrained is not None:
        restore = RestoreDepth(DepthRestorer.from_pretrained(a.pretrained, **overrides), keep_input="raw_depth")
    else:
        restore = RestoreDepth(preset=a.tier, keep_input="raw_depth", **overrides)
    ds = SyntheticScenes(n=a.frames, size=tuple(a.size), transform=Compose([Degrade(), restore]))
    t0 = time.perf_counter()  # the time from here includes the warm-up and the workers' start-up
    if a.workers > 0:  # load the model's kernels in the main process, so that the workers, forked from it, inherit
        warmup(dtypes=(torch.float32,), model=restore.restorer)  # them instead of each loading them from numba's cache
    loader = DataLoader(ds, batch_size=1, num_workers=a.workers)
    n, se_in, se_out, arrived = 0, 0.0, 0.0, []
    for b in loader:
        arrived.append(time.perf_counter())
        valid = b["mask"] > 0
        raw = b["raw_depth"]
        se_in += float((raw - b["gt"])[valid & (raw > 0)].pow(2).mean().sqrt())
        se_out += float((b["depth"] - b["gt"])[valid].pow(2).mean().sqrt())
        n += 1
    end = time.perf_counter()
    # the steady rate: from the batch by which every worker has delivered its first (start-up excluded) to the last
    w = max(1, a.workers)
    steady = (f"steady {(n - w) / (arrived[-1] - arrived[w - 1]):.2f} once every worker delivered"
              if n > w and arrived[-1] > arrived[w - 1] else "too few frames for a steady rate")
    model = f"model {a.pretrained}" if a.pretrained is not None else f"tier {a.tier}"
    print(f"{n} frames {a.size[0]}x{a.size[1]}, {model}, {a.workers} workers: {n / (end - t0):.2f} frames/s "
          f"(includes start-up; {steady}); RMSE input (measured px) "
          f"{se_in / n:.2f} -> restored {se_out / n:.2f}")


if __name__ == "__main__":
    main()
