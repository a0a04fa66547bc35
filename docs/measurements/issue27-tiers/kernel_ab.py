"""Issue 27, third stop: CPU kernels of an earlier commit against today's, on the same inputs, in one process.

    OMP_NUM_THREADS=1 python docs/measurements/issue27-tiers/kernel_ab.py --before 235f392 --threads 1
    OMP_NUM_THREADS=2 python docs/measurements/issue27-tiers/kernel_ab.py --before 235f392 --threads 2

Each kernel module of ``--before`` is read with ``git show`` into a temporary module (its imports of the package made
absolute, numba's cache off, so it compiles here) and runs beside today's module on the same input; the two are
called in turn, ``--repeats`` times each after one warm-up call, and the table gives the minimum and median
milliseconds of each and whether the outputs are equal bit for bit. Inputs: the ``sensor`` scene of stage_table.py
(flying pixels, impulses, holes) for the searches and the sided median, with the trust map ``y > 0``; for the
nonlocal terms, that scene's matches from today's search. Timing only: neither input is a benchmark scene. The
machine is shared: compare the two columns of one row, not rows of different runs.
"""
from __future__ import annotations

import argparse
import importlib.util
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from stage_table import make_input  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]
MODULES = {"search": "block_matching/cpu_exact.py", "nonlocal": "nonlocal_kernel.py", "edges": "edge_snap_kernel.py"}


def load_before(commit: str, rel: str, tmp: Path):
    """The module ``torch_depth_sr/<rel>`` as it was at ``commit``."""
    src = subprocess.run(["git", "show", f"{commit}:torch_depth_sr/{rel}"], cwd=ROOT, check=True,
                         capture_output=True, text=True).stdout
    pkg = "torch_depth_sr.block_matching" if "/" in rel else "torch_depth_sr"
    src = re.sub(r"^from \.\.(\w)", r"from torch_depth_sr.\1", src, flags=re.M)  # relative imports made absolute
    src = re.sub(r"^from \.(\w)", rf"from {pkg}.\1", src, flags=re.M)
    src = src.replace("cache=True", "cache=False")
    path = tmp / f"before_{Path(rel).stem}.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def cases(h: int, w: int):
    """``(label, module key, call(module) -> outputs)``."""
    from torch_depth_sr.block_matching import block_match

    y, rgb = make_input("sensor", h, w)
    x = y.float()
    trust = (y > 0).float()
    rho = torch.tensor([400.0])
    out = []
    for window, k in ((7, 10), (21, 10), (15, 40)):
        out.append((f"search {window}x{window}, k = {k}", "search",
                    lambda m, window=window, k=k: m.block_match_cpu_exact(x, rgb, trust, 3, window, k, rho, False,
                                                                          None, 1)))
    for k, rng in ((10, None), (40, 3.0)):
        matches = block_match(x, rgb, trust, block_size=3, search_window=7 if k == 10 else 15, k=k, color_weight=400.0)
        grad = torch.cat([x.diff(dim=-1, append=x[..., -1:]), x.diff(dim=-2, append=x[..., -1:, :])], 1)
        sigma = None if rng is None else torch.full_like(x, rng)
        out.append((f"nonlocal terms, k = {k}" + (", range weights" if rng else ""), "nonlocal",
                    lambda m, mt=matches, g=grad, s=sigma: m.nonlocal_terms_cpu(x, g, mt.index, mt.weight, 1.0, s)))
    out.append(("sided median 5x5", "edges", lambda m: m.sided_median_cpu(x, rgb, 2, 0.235, None)))
    return out


def same(a, b) -> bool:
    if isinstance(a, (tuple, list)):
        return all(same(p, q) for p, q in zip(a, b))
    return a is None and b is None or torch.equal(a, b)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--before", required=True, help="the earlier commit")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--sizes", nargs="+", default=["240x320", "480x640"], help="HxW ...")
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    after = {key: importlib.import_module(f"torch_depth_sr.{rel[:-3].replace('/', '.')}")
             for key, rel in MODULES.items()}
    with tempfile.TemporaryDirectory() as tmp:
        before = {key: load_before(a.before, rel, Path(tmp)) for key, rel in MODULES.items()}
        print(f"before = {a.before}, after = working tree; {a.threads} thread(s); ms over {a.repeats} calls each, "
              f"interleaved")
        print(f"{'size':>8}  {'kernel':<34} {'before min':>10} {'median':>8} {'after min':>10} {'median':>8}  same")
        for size in a.sizes:
            h, w = (int(v) for v in size.split("x"))
            for label, key, call in cases(h, w):
                outs = [call(before[key]), call(after[key])]
                times: list[list[float]] = [[], []]
                for _ in range(a.repeats):
                    for i, mod in enumerate((before[key], after[key])):
                        t0 = time.perf_counter()
                        call(mod)
                        times[i].append(1000 * (time.perf_counter() - t0))
                med = [sorted(t)[len(t) // 2] for t in times]
                print(f"{w}x{h:<4}  {label:<34} {min(times[0]):10.1f} {med[0]:8.1f} {min(times[1]):10.1f} "
                      f"{med[1]:8.1f}  {same(*outs)}", flush=True)


if __name__ == "__main__":
    main()
