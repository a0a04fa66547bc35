"""The numba block-matching kernel against the C kernel it replaced (issue 13 item 2), same input, same process.

The C kernel is taken from the last commit that had it (bf115a7, ``torch_depth_sr/block_matching.py``: compiled
on first use with the system ``cc -O3 -march=native``), loaded as a stand-alone module. Run from the repository
root (needs git and a C compiler):

    python docs/measurements/numba-vs-c/compare.py --threads 1 2 --repeats 5

Prints, per thread count, the median seconds of one exact pass (21×21 window, 3×3 blocks, k = 10, trust mask,
colour) at 640×480 for both kernels and the share of identical matches.
"""
import argparse
import importlib.util
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import torch

OLD_COMMIT = "bf115a7"


def load_old_module():
    src = subprocess.run(["git", "show", f"{OLD_COMMIT}:torch_depth_sr/block_matching.py"], capture_output=True,
                         text=True, check=True).stdout
    # the old module imported two helpers relatively; point them at the package
    src = src.replace("from ._checks import", "from torch_depth_sr._checks import")
    src = src.replace("from .errors import", "from torch_depth_sr.errors import")
    path = Path(tempfile.mkdtemp()) / "old_block_matching.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location("old_block_matching", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--size", type=int, nargs=2, default=(480, 640))
    a = p.parse_args()
    from torch_depth_sr.block_matching.cpu_exact import block_match_cpu_exact
    from torch_depth_sr.evaluation.speed import make_inputs

    old = load_old_module()
    lib = old._load_clib()
    if lib is None:
        sys.exit("the old C kernel could not be built here (no C compiler?)")
    y, rgb, gt = make_inputs(*a.size, 1)
    x = torch.where(y > 0, y, gt) / 5.0
    trust = (y > 0).float()
    rho = torch.tensor([400.0], dtype=torch.float64)
    args = (x, rgb, trust, 3, 21, 10, rho, False, None, 1)
    for n in a.threads:
        torch.set_num_threads(n)
        numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
        times = {"C (cc -O3 -march=native)": [], "numba": []}
        runs = {"C (cc -O3 -march=native)": lambda: old._block_match_c(lib, *args),
                "numba": lambda: block_match_cpu_exact(*args)}
        for f in runs.values():
            f()  # warm-up (compile / load)
        for _ in range(a.repeats):  # interleaved, so that a change in the machine's load hits both
            for name, f in runs.items():
                t0 = time.perf_counter()
                out = f()
                times[name].append(time.perf_counter() - t0)
        (dc, ic), (dn, i_n) = runs["C (cc -O3 -march=native)"](), runs["numba"]()
        same = float((ic == i_n).float().mean())
        print(f"{a.size[1]}x{a.size[0]}, {n} thread(s): " + ", ".join(
            f"{k} {statistics.median(v):.3f} s" for k, v in times.items()) + f"; identical matches {same:.4%}")


if __name__ == "__main__":
    main()
