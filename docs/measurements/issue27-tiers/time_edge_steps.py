"""Issue 27: the edge steps (snap, refit) on the torch path and on the numba kernels (edge_snap_kernel.py).

    python docs/measurements/issue27-tiers/time_edge_steps.py > docs/measurements/issue27-tiers/time_edge_steps.txt

The input is the ``sensor`` scene of stage_table.py (flying pixels, impulses, holes: the gate finds outliers and both
steps run); the ``fast`` preset runs once on it and forward pre-hooks keep the arguments its EdgeSnapStep and
EdgeRefitStep receive (x in units of the scale, the measurements, the colour, the active samples), so each step is
timed on exactly what the model passes it. Each figure is the minimum of 5 runs after one warm-up run (the machine
is shared). The torch path is forced by ``TORCH_DEPTH_SR_NO_NUMBA=1`` around its runs. "moved": the pixels the torch
path changes; "differ": the pixels where the two results differ (a share at exactly the threshold, where the two
paths' sums round differently, or a median tie at exactly half the weight).
"""
from __future__ import annotations

import os
import sys
import time

import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from stage_table import make_input  # noqa: E402

from torch_depth_sr import DepthRestorer  # noqa: E402
from torch_depth_sr.edge_snap import refit_to_measurements, snap_to_sides  # noqa: E402
from torch_depth_sr.post_steps import EdgeRefitStep, EdgeSnapStep  # noqa: E402

REPEATS = 5


def captured_calls(h: int, w: int) -> dict:
    """``{"snap": (call, x), "refit": (call, x)}``: each step's function with the arguments the fast model gives it,
    and its input ``x``."""
    model = DepthRestorer.from_preset("fast")
    held = {}

    def keep(name):
        def hook(module, args):
            held[name] = (module.settings, *args)
        return hook

    for steps in model.post.values():
        for step in steps:
            if isinstance(step, EdgeSnapStep):
                step.register_forward_pre_hook(keep("snap"))
            elif isinstance(step, EdgeRefitStep):
                step.register_forward_pre_hook(keep("refit"))
    y, rgb = make_input("sensor", h, w)
    with torch.no_grad():
        model(y, rgb)
    calls = {}
    for name in held:
        c, x, state, obs, _ = held[name]
        calls[name] = (_call(name, c, x.detach().clone(), obs, ~state.clean), x)
    return calls


def _call(name, c, x, obs, active):
    if name == "snap":
        return lambda: snap_to_sides(x, obs.rgb, rounds=c.rounds, radius=c.radius, share=c.share,
                                     sigma_color=c.sigma_color, sigma_space=c.sigma_space, active=active)
    return lambda: refit_to_measurements(x, obs.y, obs.observed, obs.rgb, radius=c.radius, band=c.band, edge=c.edge,
                                         sigma_color=c.sigma_color, active=active)


def best(call) -> tuple[float, torch.Tensor]:
    with torch.no_grad():
        out = call()
        seconds = []
        for _ in range(REPEATS):
            t0 = time.perf_counter()
            call()
            seconds.append(time.perf_counter() - t0)
    return min(seconds), out


def main() -> None:
    print(f"torch {torch.__version__}; minimum of {REPEATS} runs; seconds per call; moved = pixels the step changes")
    print(f"{'size':>8} {'threads':>7} {'step':>5} {'torch':>8} {'kernel':>8} {'speed-up':>8} {'moved':>7} {'differ':>6}")
    for (h, w), threads in (((240, 320), 1), ((480, 640), 2)):
        torch.set_num_threads(threads)
        calls = captured_calls(h, w)
        for step in ("snap", "refit"):
            if step not in calls:
                print(f"{w}x{h:<4} {threads:>7} {step:>5}  (the model did not run this step)")
                continue
            os.environ["TORCH_DEPTH_SR_NO_NUMBA"] = "1"
            call, x = calls[step]
            t_torch, ref = best(call)
            del os.environ["TORCH_DEPTH_SR_NO_NUMBA"]
            t_kernel, out = best(call)
            moved = int((ref != x).sum())
            print(f"{w}x{h:<4} {threads:>7} {step:>5} {t_torch:8.4f} {t_kernel:8.4f} {t_torch / t_kernel:7.1f}x "
                  f"{moved:>7} {int((out != ref).sum()):>6}")


if __name__ == "__main__":
    main()
