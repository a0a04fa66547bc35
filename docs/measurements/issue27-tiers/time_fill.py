"""Issue 27: ``fill_holes_sided`` on the CPU, the torch path (``fill._fill_pixels`` per pass) against the numba
kernel (``fill_kernel.py``), on the arguments the ``fast`` model's x⁰ passes it.

    python docs/measurements/issue27-tiers/time_fill.py [--base REV] > docs/measurements/issue27-tiers/time_fill.txt

``--base REV`` (default fb38f7d, the last commit before the kernel) adds a column: the ``fill.py`` of that git
revision (its torch path and its pass loop, which ran ``nonzero`` and four-index writes over the planes each pass),
loaded from ``git show`` beside the current package. "torch" is the current loop with ``fill._fill_pixels``,
"kernel" the current loop with the numba kernel.

The arguments are captured from one forward of ``DepthRestorer.from_preset("fast")`` (a wrapper around
``initial.fill_holes_sided``): the depth normalised by the model's noise scale, the mask, the guide on the depth's
grid, the window and the ``sided_fill`` settings. Inputs: ``stage_table.make_input`` (``synthetic``: the scene
``bench --track speed`` times, about 5 % holes; ``sensor``: the same scene degraded by the ``sensor`` protocol).
Each figure is the minimum of 5 calls after one warm-up call (the machine is shared: the minimum is the least
disturbed); the kernel's first call also loads or compiles it, outside the timing.
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import subprocess
import sys
import time

import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from stage_table import make_input  # noqa: E402

from torch_depth_sr import DepthRestorer, fill, initial  # noqa: E402

REPEATS = 5


def capture(kind: str, h: int, w: int):
    """The ``(args, kwargs)`` of the ``fill_holes_sided`` call inside one ``fast`` forward."""
    y, rgb = make_input(kind, h, w)
    seen = []
    real = initial.fill_holes_sided

    def spy(*args, **kwargs):
        seen.append((tuple(a.clone() if torch.is_tensor(a) else a for a in args), dict(kwargs)))
        return real(*args, **kwargs)

    initial.fill_holes_sided = spy
    try:
        with torch.no_grad():
            DepthRestorer.from_preset("fast")(y, rgb)
    finally:
        initial.fill_holes_sided = real
    assert len(seen) == 1, len(seen)
    return seen[0]


def load_base(rev: str):
    """``torch_depth_sr/fill.py`` as of git revision ``rev``, as the module ``torch_depth_sr._fill_base``."""
    src = subprocess.run(["git", "show", f"{rev}:torch_depth_sr/fill.py"], capture_output=True, text=True,
                         check=True).stdout
    spec = importlib.util.spec_from_loader("torch_depth_sr._fill_base", loader=None)
    mod = importlib.util.module_from_spec(spec)
    mod.__package__ = "torch_depth_sr"
    exec(compile(src, f"{rev}:torch_depth_sr/fill.py", "exec"), mod.__dict__)
    return mod


def best(call) -> float:
    call()
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        call()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--base", default="fb38f7d", help="git revision of the fill.py to time beside (''=none)")
    a = p.parse_args()
    base = load_base(a.base) if a.base else None
    kernel = fill._kernel()
    assert kernel is not None, "numba is needed for the kernel's column"
    rows = []
    for h, w, threads in ((480, 640, 2), (240, 320, 1)):
        torch.set_num_threads(threads)
        for kind in ("synthetic", "sensor"):
            args, kwargs = capture(kind, h, w)
            holes = float((args[1] <= 0).float().mean())
            passes = []

            def count(p, bi, yi, xi):
                passes.append(len(bi))
                return kernel(p, bi, yi, xi)

            fill._kernel = lambda: count
            with torch.no_grad():
                fast = fill.fill_holes_sided(*args, **kwargs)
            fill._kernel = lambda: None
            with torch.no_grad():
                ref = fill.fill_holes_sided(*args, **kwargs)
                t_torch = best(lambda: fill.fill_holes_sided(*args, **kwargs))
            fill._kernel = lambda: kernel
            with torch.no_grad():
                t_kernel = best(lambda: fill.fill_holes_sided(*args, **kwargs))
                t_base = best(lambda: base.fill_holes_sided(*args, **kwargs)) if base is not None else float("nan")
                if base is not None:
                    assert torch.equal(base.fill_holes_sided(*args, **kwargs).depth, ref.depth)
            diff = float((fast.depth - ref.depth).abs().max())
            conf = int((fast.confident != ref.confident).sum())
            rows.append((f"{w}x{h}", threads, kind, holes, len(passes), t_base, t_torch, t_kernel, diff, conf))
    print(f"fill_holes_sided on the CPU, the fast model's arguments (kernel_size {kwargs['kernel_size']}, "
          f"choice_sigma_space {kwargs.get('choice_sigma_space')}, passes {kwargs.get('passes')}), "
          f"min of {REPEATS}; torch {torch.__version__}")
    print(f"{'size':>8} {'thr':>3} {'input':>9} {'holes':>6} {'passes':>6} {'base s':>9} {'torch s':>9} "
          f"{'kernel s':>9} {'torch/k':>7} {'base/k':>7} {'max |Δdepth|':>12} {'Δconf px':>8}")
    for size, thr, kind, holes, npass, tb, tt, tk, diff, conf in rows:
        print(f"{size:>8} {thr:>3} {kind:>9} {holes:6.1%} {npass:6d} {tb:9.4f} {tt:9.4f} {tk:9.4f} {tt / tk:6.1f}x "
              f"{tb / tk:6.1f}x {diff:12.2e} {conf:8d}")
    print(f"(base: fill.py of {a.base or '-'}, torch path, same depth as the current torch path; max |Δdepth|, "
          "Δconf px: kernel against the torch path, depth in the model's noise-σ units)")


if __name__ == "__main__":
    main()
