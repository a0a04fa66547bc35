"""Issue 27, second stop: the small exact changes, each against what it replaced, at 640x480, 2 threads.

    python docs/measurements/issue27-tiers/time_small_steps.py

* the window maximum (``window_max.max_filter``) against stride-1 ``max_pool2d`` (refiner bounds 3x3, refit 5x5);
* the singular support rule in one look at the neighbours (``singular.supported_or_line``) against the neighbour
  count and the line test called apart (what ``stages._neighbours_or_line`` did);
* the cost of ``torch.broadcast_shapes``' first call in a fresh process (it imports sympy), which the shrinkage's
  shape check no longer pays (``numpy.broadcast_shapes``), and of a fresh process's first and second forward of the
  ``fast`` tier on a 320x240 sensor frame.

Each figure is the minimum of 7 calls (the processes: one run each); the outputs are checked equal.
"""
import subprocess
import sys
import time

import torch
import torch.nn.functional as F

from torch_depth_sr.singular import line_support, neighbour_support, supported_or_line
from torch_depth_sr.window_max import max_filter


def best(f, n=7):
    f()
    t = []
    for _ in range(n):
        t0 = time.perf_counter()
        f()
        t.append(time.perf_counter() - t0)
    return min(t)


def main() -> None:
    torch.set_num_threads(2)
    sys.path.insert(0, "docs/measurements/issue27-tiers")
    from stage_table import make_input

    y, _ = make_input("sensor", 480, 640)
    x = y / 3.0
    print("step                                   before ms  after ms")
    for size in (3, 5):
        assert torch.equal(max_filter(x, size), F.max_pool2d(x, size, 1, size // 2))
        print(f"window max {size}x{size}                         {best(lambda: F.max_pool2d(x, size, 1, size // 2)) * 1e3:8.1f}"
              f"  {best(lambda: max_filter(x, size)) * 1e3:8.1f}")
    obs = (y > 0).float()
    tol = torch.tensor(2.0)
    apart = lambda: (neighbour_support(x, obs, tol) >= 3) | line_support(x, obs, tol)  # noqa: E731
    assert torch.equal(apart(), supported_or_line(x, obs, tol, 3))
    print(f"singular support (count | line)          {best(apart) * 1e3:8.1f}  {best(lambda: supported_or_line(x, obs, tol, 3)) * 1e3:8.1f}")
    probe = ("import time, torch; t0 = time.perf_counter(); torch.broadcast_shapes((2, 1), (2, 3)); "
             "print(f'{(time.perf_counter() - t0) * 1e3:.0f}')")
    ms = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True).stdout.strip()
    print(f"torch.broadcast_shapes, first call       {ms:>8}  (not called)")
    first = ("import sys, time, torch; sys.path.insert(0, 'docs/measurements/issue27-tiers'); "
             "from stage_table import make_input; from torch_depth_sr import DepthRestorer; "
             "m = DepthRestorer.from_preset('fast'); y, rgb = make_input('sensor', 240, 320); torch.set_num_threads(1); "
             "t0 = time.perf_counter(); m(y, rgb); t1 = time.perf_counter(); m(y, rgb); t2 = time.perf_counter(); "
             "print(f'{(t1 - t0) * 1e3:.0f} {(t2 - t1) * 1e3:.0f}')")
    a, b = subprocess.run([sys.executable, "-c", first], capture_output=True, text=True).stdout.split()
    print(f"fast, 320x240 sensor frame, 1 thread: a process's first forward {a} ms, its second {b} ms")


if __name__ == "__main__":
    main()
