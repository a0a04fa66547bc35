"""Cost of numba's first use: import, first forward (kernels compiled or loaded from the cache), second forward.

    d=$(mktemp -d); NUMBA_CACHE_DIR=$d python docs/measurements/numba-first-use/first_forward.py   # empty cache
    NUMBA_CACHE_DIR=$d python docs/measurements/numba-first-use/first_forward.py                  # cache filled
"""
import time

t0 = time.perf_counter()
from torch_depth_sr import DepthRestorer  # noqa: E402
from torch_depth_sr.evaluation.speed import make_inputs  # noqa: E402

y, rgb, gt = make_inputs(120, 160, 1)
t1 = time.perf_counter()
DepthRestorer()(y, rgb)
t2 = time.perf_counter()
DepthRestorer()(y, rgb)
t3 = time.perf_counter()
print(f"import {t1 - t0:.1f} s, first forward {t2 - t1:.1f} s, second forward {t3 - t2:.2f} s")
