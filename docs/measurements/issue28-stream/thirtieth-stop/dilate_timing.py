"""Issue 28, thirtieth stop: milliseconds of the bool dilation (median of 20 calls) on random masks at 463×370 and
1376×1088, 2 threads: ``window_max.dilate``, ``stream.matching.dilate`` in trees before this stop. Run once per
tree, from /tmp (``PYTHONPATH`` picks the tree):

    cd /tmp && PYTHONPATH=/path/to/tree GOMP_SPINCOUNT=10000 python /path/to/dilate_timing.py
"""
import time

import numpy as np
import torch

try:
    from torch_depth_sr.window_max import dilate
except ImportError:  # before this stop
    from torch_depth_sr.stream.matching import dilate


def median_ms(fn, n: int = 20) -> float:
    fn()
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def main() -> None:
    torch.set_num_threads(2)
    g = torch.Generator().manual_seed(0)
    for h, w in ((370, 463), (1088, 1376)):
        for share in (0.004, 0.05):
            mask = torch.rand(1, 1, h, w, generator=g) < share
            print(f"{w}x{h} set {share:.1%}: radius 2 {median_ms(lambda: dilate(mask, 2)):.2f} ms, "
                  f"radius 4 {median_ms(lambda: dilate(mask, 4)):.2f} ms")


if __name__ == "__main__":
    main()
