"""``python -m torch_depth_sr.evaluation.gpu_report``: time every speed tier on a CUDA GPU in one command.

``python -m torch_depth_sr.evaluation.gpu_report [--sizes 480x640 1088x1376] [--batch 1 8] [--out DIR]`` times, per
size (height x width) and batch, the tiers ``fast``, ``default`` and ``best``, the stream's own model
``denoise-fast`` (the fast tier until 2026-12-05) on a cold frame, a stream step of that model and of the default
tier (``stream-fast``, ``stream``: :class:`~torch_depth_sr.StreamRestorer` on the scene of the tiers' frames with new
noise every step, after its cold first frame and ``speed.STREAM_WARM_STEPS`` steps; ``step_vs_cold`` is the step's
time over its model's cold row) and kornia's ``joint_bilateral_blur`` 9x9 as the reference: warm-up calls, then the
median ms per frame of ``--repeats`` calls timed with CUDA events, the peak memory
(``torch.cuda.max_memory_allocated`` over what was allocated before), and for each tier an attempt to capture its
forward as a CUDA graph (static inputs) with the replay's ms per frame, or the error text and where it arose.
It prints a table and writes ``gpu_report.json`` and ``gpu_report.md`` under ``--out``. Without CUDA it prints one
line and exits with status 2.

The functions below ``main``'s table are the earlier parts of the report (run on any device by the tests; not by
``main``):

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
import traceback
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
                same = torch.equal(torch_search.smallest_keys(keys, c.k, how), expected)
                row[how] = _timed(lambda: torch_search.smallest_keys(keys, c.k, how), device, repeats)
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


TIERS = ("fast", "default", "best")
STREAMS = {"stream-fast": "denoise-fast", "stream": "default"}  # a stream step and the model it runs (cold row)
COLUMNS = ["method", "size", "batch", "ms_per_frame", "step_vs_cold", "peak_mb", "graph", "graph_ms_per_frame",
           "graph_max_abs_diff"]


def _event_ms(fn, repeats: int, warmup: int) -> float:
    """Median milliseconds of ``fn()`` after ``warmup`` calls, each timed by CUDA events around it."""
    for _ in range(warmup):
        fn()
    torch.cuda.synchronize()
    times = []
    for _ in range(repeats):
        start, end = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
        start.record()
        fn()
        end.record()
        end.synchronize()
        times.append(start.elapsed_time(end))
    return statistics.median(times)


def _peak_mb(fn) -> float:
    """MB that one call of ``fn`` allocated at its peak over what was allocated before it."""
    torch.cuda.synchronize()
    before = torch.cuda.memory_allocated()
    torch.cuda.reset_peak_memory_stats()
    fn()
    torch.cuda.synchronize()
    return (torch.cuda.max_memory_allocated() - before) / 2 ** 20


def _graph(model, depth: torch.Tensor, rgb: torch.Tensor, repeats: int, warmup: int) -> dict:
    """Capture ``model(depth, rgb)`` as a CUDA graph on static copies of the inputs and time its replay; the
    error's first line instead when the capture fails (the report goes on)."""
    static_depth, static_rgb = depth.clone(), rgb.clone()
    try:
        side = torch.cuda.Stream()  # warm-up on a side stream before capturing, as torch.cuda.graphs asks
        side.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(side), torch.no_grad():
            for _ in range(2):
                model(static_depth, static_rgb)
        torch.cuda.current_stream().wait_stream(side)
        graph = torch.cuda.CUDAGraph()
        with torch.no_grad(), torch.cuda.graph(graph):
            static_out = model(static_depth, static_rgb)
        ms = _event_ms(graph.replay, repeats, warmup)
        graph.replay()
        with torch.no_grad():
            eager = model(static_depth, static_rgb)
        diff = float((static_out - eager).abs().max())
        return {"graph": "captured", "graph_ms_per_frame": ms / depth.shape[0], "graph_max_abs_diff": diff}
    except Exception as exc:  # any failure of the capture is a result to report, not a crash
        first = (str(exc).strip().splitlines() or [""])[0]
        ours = [f for f in traceback.extract_tb(exc.__traceback__) if "torch_depth_sr/" in f.filename]
        at = f" (at {ours[-1].filename.split('torch_depth_sr/')[-1]}:{ours[-1].lineno})" if ours else ""
        return {"graph": f"failed{at}: {type(exc).__name__}: {first}"[:300]}


def _kornia_jbf9(depth: torch.Tensor, rgb: torch.Tensor) -> torch.Tensor:
    import kornia

    return kornia.filters.joint_bilateral_blur(depth, rgb, (9, 9), 0.1, (3.0, 3.0))


def stream_step(model: DepthRestorer, depth: torch.Tensor, rgb: torch.Tensor, gt: torch.Tensor, seed: int = 1,
                noise_device: Optional[str] = None):
    """A function that feeds a new :class:`~torch_depth_sr.StreamRestorer` of ``model`` the next frame of a static
    scene: ``gt`` with new noise (σ = 5, as :func:`speed.make_inputs`) and ``depth``'s holes, on the inputs' device.
    Its first call is the stream's cold frame; call it ``speed.STREAM_WARM_STEPS`` times more before timing steps.
    The noise is drawn on ``noise_device`` (default: the inputs'; ``"cpu"`` gives the same frames on every device,
    for comparisons, at the price of a copy per step)."""
    from ..stream import StreamRestorer

    stream = StreamRestorer(model)
    noise_device = noise_device or depth.device
    g = torch.Generator(device=noise_device).manual_seed(seed)
    holes = depth <= 0

    def step():
        noise = 5.0 * torch.randn(depth.shape, generator=g, device=noise_device, dtype=depth.dtype).to(depth.device)
        return stream.step(torch.where(holes, torch.zeros_like(depth), (gt + noise).clamp_min(1.0)), rgb)

    return step


def measure_all(sizes: Sequence[tuple[int, int]], batches: Sequence[int], repeats: int, warmup: int) -> list[dict]:
    """One row per (method, size, batch) on ``cuda``: the tiers, the stream steps, then kornia's 9x9 joint bilateral
    filter."""
    rows = []
    models = {tier: DepthRestorer.from_preset(tier).to("cuda").eval() for tier in TIERS}
    models.update({name: DepthRestorer.from_pretrained(name).to("cuda").eval()  # the stream models that are no tier
                   for name in STREAMS.values() if name not in models})
    for h, w in sizes:
        for b in batches:
            depth, rgb, gt = speed.make_inputs(h, w, b)
            depth, rgb, gt = depth.to("cuda"), rgb.to("cuda"), gt.to("cuda")
            runs = {tier: (lambda m=m: m(depth, rgb)) for tier, m in models.items()}
            runs.update({name: stream_step(models[tier], depth, rgb, gt) for name, tier in STREAMS.items()})
            runs["kornia-jbf9"] = lambda: _kornia_jbf9(depth, rgb)
            cold = {}
            for name, run in runs.items():
                row = {"method": name, "size": f"{h}x{w}", "batch": b}
                try:
                    with torch.no_grad():
                        for _ in range(1 + speed.STREAM_WARM_STEPS if name in STREAMS else 0):
                            run()  # the stream's cold first frame and the steps that fill its state
                        row["ms_per_frame"] = _event_ms(run, repeats, warmup) / b
                        row["peak_mb"] = _peak_mb(run)
                except torch.cuda.OutOfMemoryError as exc:
                    row["error"] = f"out of memory: {str(exc).splitlines()[0]}"[:300]
                    torch.cuda.empty_cache()
                except Exception as exc:  # a method that fails on the GPU is a result to report; the others go on
                    first = (str(exc).strip().splitlines() or [""])[0]
                    row["error"] = f"{type(exc).__name__}: {first}"[:300]
                if name in models and "error" not in row:
                    cold[name] = row["ms_per_frame"]
                if name in STREAMS and "error" not in row and STREAMS[name] in cold:
                    row["step_vs_cold"] = row["ms_per_frame"] / cold[STREAMS[name]]
                if name in TIERS and "error" not in row:
                    row.update(_graph(models[name], depth, rgb, repeats, warmup))
                rows.append(row)
                print(format_table([row], header=not rows[:-1]), flush=True)
    return rows


def _cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.3g}" if abs(v) < 100 else f"{v:.0f}"
    return str(v)


def format_table(rows: Sequence[dict], header: bool = True) -> str:
    """A Markdown table of report rows (the columns of :data:`COLUMNS`, then ``error`` when a row has one)."""
    cols = COLUMNS + (["error"] if any("error" in r for r in rows) else [])
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)] if header else []
    lines += ["| " + " | ".join(_cell(r.get(c)) for c in cols) + " |" for r in rows]
    return "\n".join(lines)


def _size(text: str) -> tuple[int, int]:
    try:
        h, w = (int(t) for t in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"a size is HEIGHTxWIDTH, e.g. 480x640; got {text!r}") from None
    return h, w


NO_GPU = "gpu_report: no GPU is available (torch.cuda.is_available() is False); nothing was measured."


def main(argv: Optional[Sequence[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", nargs="+", type=_size, default=[(480, 640), (1088, 1376)], help="HEIGHTxWIDTH ...")
    p.add_argument("--batch", nargs="+", type=int, default=[1, 8])
    p.add_argument("--out", default="out/gpu")
    p.add_argument("--repeats", type=int, default=10)
    p.add_argument("--warmup", type=int, default=3)
    a = p.parse_args(argv)
    if not torch.cuda.is_available():
        print(NO_GPU)
        return 2
    from .report import metadata

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    meta = metadata("cuda")
    print(meta, flush=True)
    rows = measure_all(a.sizes, a.batch, a.repeats, a.warmup)
    (out / "gpu_report.json").write_text(json.dumps({"metadata": meta, "rows": rows}, indent=1, default=str))
    (out / "gpu_report.md").write_text(f"GPU report, commit {meta.get('commit')}, {meta.get('gpu', meta.get('device'))}"
                                       f"\n\n{format_table(rows)}\n")
    print(f"wrote {out / 'gpu_report.json'} and {out / 'gpu_report.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
