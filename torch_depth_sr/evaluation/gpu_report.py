"""``python -m torch_depth_sr.evaluation.gpu_report``: check and time the model on a CUDA GPU in one run.

Four parts, printed as tables and written as JSON under ``--out``:

1. **agreement** — the GPU path (torch block matching, torch singular test) against the CPU path
   (numba kernels; both with exact re-matching) on the same synthetic frames: share of identical matches, largest distance
   difference, largest output difference, and the RMSE of each against the ground truth;
2. **selection** — the ways of taking the k smallest block-matching keys (all exact), timed alone
   at 640×480 (the model uses ``"split"``; the record of the choice is in ``docs/measurements``);
3. **speed** — the speed track (:mod:`torch_depth_sr.evaluation.speed`) on the GPU, in this process
   (``torch.cuda.max_memory_allocated`` is reset per row), every size and batch 1 and 8;
4. **profile** — one 640×480 forward under ``torch.profiler``: the kernels that take the time and
   how many launches there are (``profile.txt``).

The accuracy of the benchmark tracks on the GPU is measured separately with
``torch-depth-sr bench --track paper --device cuda`` (needs the data).
"""
from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Optional, Sequence

import torch

from ..block_matching import torch_search
from ..block_matching import block_match
from ..model import DepthRestorer
from . import speed

__all__ = ["agreement", "matching_times", "selection_times", "profile", "main"]


def _timed(fn, device: str, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        speed._sync(device)
        t0 = time.perf_counter()
        fn()
        speed._sync(device)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def agreement(device: str, height: int, width: int, batch: int) -> dict:
    """GPU against CPU on the same inputs (matching and the whole model)."""
    y, rgb, gt = speed.make_inputs(height, width, batch, seed=3)
    # the GPU always re-matches exactly; the CPU default refines
    model = DepthRestorer(block_matching={"rematch": "exact"})
    c = model.config.block_matching
    x = torch.where(y > 0, y, y[y > 0].mean()) / 255.0
    args = dict(block_size=c.block_size, search_window=c.search_window, k=c.k)
    m_cpu = block_match(x, rgb, None, **args)
    m_gpu = block_match(x.to(device), rgb.to(device), None, **args)
    with torch.no_grad():
        out_cpu = model(y, rgb)
        out_gpu = model.to(device)(y.to(device), rgb.to(device)).cpu()
    rmse = lambda a: float((a - gt).pow(2).mean().sqrt())  # noqa: E731
    return {"size": f"{width}x{height}", "batch": batch,
            "matches_equal": float((m_cpu.index == m_gpu.index.cpu()).double().mean()),
            "dist_max_abs_diff": float((m_cpu.dist - m_gpu.dist.cpu()).abs().max()),
            "out_max_abs_diff": float((out_cpu - out_gpu).abs().max()),
            "out_rmse_cpu": rmse(out_cpu), "out_rmse_gpu": rmse(out_gpu), "input_rmse": rmse(y)}


def matching_times(device: str, sizes: Sequence[tuple[int, int]], batches: Sequence[int], repeats: int) -> list[dict]:
    """One block-matching pass (21×21 window, the model's block and k) per size and batch."""
    c = DepthRestorer().config.block_matching
    rows = []
    for h, w in sizes:
        for b in batches:
            y, rgb, _ = speed.make_inputs(h, w, b)
            x, g = (y / 255.0).to(device), rgb.to(device)
            t = _timed(lambda: block_match(x, g, None, block_size=c.block_size, search_window=c.search_window,
                                           k=c.k), device, repeats)
            rows.append({"size": f"{w}x{h}", "batch": b, "seconds": t, "ms_per_frame": 1000 * t / b})
    return rows


def selection_times(device: str, sizes: Sequence[tuple[int, int]], batches: Sequence[int], repeats: int) -> list[dict]:
    """Each way of taking the k smallest of the block-matching keys, on keys shaped like the model's."""
    c = DepthRestorer().config.block_matching
    n = c.search_window ** 2
    rows = []
    for h, w in sizes:
        for b in batches:
            g = torch.Generator(device=device).manual_seed(0)
            keys = torch.randint(0, 2 ** 62, (b, h * w, n), device=device, generator=g)
            expected = torch.sort(keys, dim=2).values[..., :c.k]
            row = {"size": f"{w}x{h}", "batch": b}
            for how in torch_search._SELECT_CHOICES:
                same = torch.equal(torch_search._smallest_keys(keys, c.k, how), expected)
                row[how] = _timed(lambda: torch_search._smallest_keys(keys, c.k, how), device, repeats)
                row[how + "_exact"] = same
            rows.append(row)
            del keys, expected
    return rows


def profile(device: str, height: int, width: int, path: Path) -> dict:
    from torch.profiler import ProfilerActivity, profile as torch_profile

    y, rgb, _ = speed.make_inputs(height, width, 1)
    y, rgb = y.to(device), rgb.to(device)
    model = DepthRestorer().to(device)
    with torch.no_grad():
        model(y, rgb)
        speed._sync(device)
        acts = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if device.startswith("cuda") else [])
        with torch_profile(activities=acts) as prof:
            model(y, rgb)
            speed._sync(device)
    avg = prof.key_averages()
    key = "cuda_time_total" if device.startswith("cuda") else "cpu_time_total"
    try:
        table = avg.table(sort_by=key, row_limit=40)
    except Exception:  # newer torch names it device_time_total
        table = avg.table(sort_by="device_time_total", row_limit=40)
    path.write_text(table)
    launches = sum(e.count for e in avg if getattr(e, "device_type", None) is not None
                   and str(e.device_type).endswith("CUDA"))
    return {"kernel_launches": launches, "ops": sum(e.count for e in avg)}


def main(argv: Optional[Sequence[str]] = None) -> int:
    from .report import metadata as _metadata, print_table as _print_table

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cuda")
    p.add_argument("--out", default="out/gpu")
    p.add_argument("--sizes", default="370x463,480x640,1088x1376")
    p.add_argument("--batches", default="1,8")
    p.add_argument("--repeats", type=int, default=10)
    p.add_argument("--skip", default="dictionary@1088x1376x8",
                   help="comma-separated method@HxWxB rows of the speed table not to run")
    a = p.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    sizes, batches = speed._parse_sizes(a.sizes), speed._parse_ints(a.batches)
    report = {"metadata": _metadata(a.device)}
    print(report["metadata"], flush=True)

    report["agreement"] = [agreement(a.device, *sizes[min(1, len(sizes) - 1)], 1), agreement(a.device, 64, 80, 3)]
    _print_table(report["agreement"], list(report["agreement"][0]), "GPU against CPU (same synthetic inputs)")

    vga = [(480, 640)]  # the selection study at 640×480 whatever --sizes says (larger key stacks pass 2³¹ elements)
    report["selection"] = sel = selection_times(a.device, vga, batches, a.repeats)
    _print_table(sel, list(sel[0]), "top-k selection of the block-matching keys (seconds; the model uses 'split')")
    report["block_matching"] = matching_times(a.device, sizes, batches, a.repeats)
    _print_table(report["block_matching"], ["size", "batch", "seconds", "ms_per_frame"], "one block-matching pass")

    report["profile"] = profile(a.device, *sizes[min(1, len(sizes) - 1)], out / "profile.txt")
    print(report["profile"], flush=True)
    (out / "gpu_report.json").write_text(json.dumps(report, indent=1))

    ns = argparse.Namespace(device=a.device, sizes=sizes, batches=batches, repeats=a.repeats, isolate=False,
                            skip=tuple(t for t in a.skip.split(",") if t), max_seconds=30.0,
                            methods=list(speed.METHODS), json=str(out / "speed.json"))
    return speed.run_speed(ns)


if __name__ == "__main__":
    raise SystemExit(main())
