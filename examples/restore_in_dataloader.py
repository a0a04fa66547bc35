"""Clean depth inside a data pipeline: RestoreDepth per sample in DataLoader workers (CPU).

    python examples/restore_in_dataloader.py --workers 2 --frames 8 --size 240 320

On a GPU, restore after collation instead (batched):
    restore = RestoreDepth(device="cuda"); batch = restore({"depth": depth.cuda(), "rgb": rgb.cuda()})
"""
import argparse
import time

import torch
from torch.utils.data import DataLoader

from torch_depth_sr.datasets.synthetic import SyntheticScenes
from torch_depth_sr.degradations import SensorDegradation
from torch_depth_sr.transforms import Compose, RestoreDepth


class Degrade:
    """Sensor degradation (noise, holes, flying pixels) keeping only the keys we batch."""

    def __call__(self, s):
        s = SensorDegradation(seed=0)(s)
        return {k: s[k] for k in ("depth", "rgb", "gt", "mask", "name")}


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--frames", type=int, default=8)
    p.add_argument("--size", type=int, nargs=2, default=(240, 320))
    p.add_argument("--layers", type=int, default=8)
    a = p.parse_args()
    restore = RestoreDepth(num_layers=a.layers, keep_input="raw_depth")
    ds = SyntheticScenes(n=a.frames, size=tuple(a.size), transform=Compose([Degrade(), restore]))
    loader = DataLoader(ds, batch_size=1, num_workers=a.workers)
    t0, n, se_in, se_out = time.perf_counter(), 0, 0.0, 0.0
    for b in loader:
        valid = b["mask"] > 0
        raw = b["raw_depth"]
        se_in += float((raw - b["gt"])[valid & (raw > 0)].pow(2).mean().sqrt())
        se_out += float((b["depth"] - b["gt"])[valid].pow(2).mean().sqrt())
        n += 1
    dt = time.perf_counter() - t0
    print(f"{n} frames {a.size[0]}x{a.size[1]}, {a.workers} workers: {n / dt:.2f} frames/s "
          f"(includes worker start-up); RMSE input (measured px) {se_in / n:.2f} -> restored {se_out / n:.2f}")


if __name__ == "__main__":
    main()
