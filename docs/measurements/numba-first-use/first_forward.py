"""Cost of numba's first use: import, first forward (kernels compiled or loaded from the cache), second forward,
and each kernel's compile time (numba's ``numba:compile`` events; nested compiles are counted inside their caller).

    d=$(mktemp -d); NUMBA_CACHE_DIR=$d python docs/measurements/numba-first-use/first_forward.py   # empty cache
    NUMBA_CACHE_DIR=$d python docs/measurements/numba-first-use/first_forward.py                  # cache filled

NUMBA_CACHE_DIR keeps the measurement away from the __pycache__ folders next to the kernels (where numba's
``cache=True`` writes otherwise), so an empty folder is an empty cache. Options: ``--size HxW`` (default 240x320),
``--dtype float32|float64``, ``--preset fast``, ``--threads N`` (default 2), ``--no-second``.
"""
import argparse
import os
import sys
import time

p = argparse.ArgumentParser()
p.add_argument("--size", default="240x320")
p.add_argument("--dtype", default="float32", choices=["float32", "float64"])
p.add_argument("--preset", default=None)
p.add_argument("--threads", type=int, default=2)
p.add_argument("--no-second", action="store_true")
args = p.parse_args()
h, w = (int(v) for v in args.size.split("x"))

t0 = time.perf_counter()
import torch  # noqa: E402

torch.set_num_threads(args.threads)
from numba.core import event  # noqa: E402

from torch_depth_sr import DepthRestorer  # noqa: E402
from torch_depth_sr.evaluation.speed import make_inputs  # noqa: E402

compiles = []  # (depth, name, signature, wall seconds, CPU seconds of the compiling thread)


class _Compiles(event.Listener):
    def __init__(self):
        self.stack = []

    def on_start(self, ev):
        self.stack.append((time.perf_counter(), time.thread_time()))

    def on_end(self, ev):
        start, cpu = self.stack.pop()
        d = ev.data or {}
        disp = d.get("dispatcher")
        name = getattr(getattr(disp, "py_func", None), "__qualname__", str(disp))
        mod = getattr(getattr(disp, "py_func", None), "__module__", "").replace("torch_depth_sr.", "")
        sig = ", ".join(str(a) for a in d.get("args", ()))
        compiles.append((len(self.stack), f"{mod}.{name}", sig, time.perf_counter() - start, time.thread_time() - cpu))


event.register("numba:compile", _Compiles())

dt = getattr(torch, args.dtype)
y, rgb, gt = make_inputs(h, w, 1)
y, rgb = y.to(dt), rgb.to(dt)
make = (lambda: DepthRestorer.from_preset(args.preset)) if args.preset else DepthRestorer
t1, c1 = time.perf_counter(), time.process_time()
make()(y, rgb)
t2, c2 = time.perf_counter(), time.process_time()
line = (f"{h}x{w} {args.dtype} preset={args.preset} threads={torch.get_num_threads()} "
        f"cache={os.environ.get('NUMBA_CACHE_DIR', '(next to the modules)')}: "
        f"import {t1 - t0:.1f} s, first forward {t2 - t1:.1f} s ({c2 - c1:.1f} s CPU)")
if not args.no_second:
    make()(y, rgb)
    line += f", second forward {time.perf_counter() - t2:.1f} s ({time.process_time() - c2:.1f} s CPU)"
print(line)
top = [c for c in compiles if c[0] == 0]
print(f"compiled {len(top)} top-level kernel signature(s) ({len(compiles)} with nested): "
      f"{sum(c[3] for c in top):.1f} s ({sum(c[4] for c in top):.1f} s CPU) in all")
for depth, name, sig, secs, _ in compiles:
    if secs >= 0.05 and (depth == 0 or name.startswith(("block_matching", "nonlocal", "singular")) or secs >= 1):
        print(f"  {'  ' * depth}{secs:6.2f} s  {name}({sig[:120]})")
sys.stdout.flush()
