"""``torch-depth-sr bench --track speed``: time and peak memory of the model, its stages and the filters.

Times, side by side in one run and on the same synthetic inputs
(:func:`~torch_depth_sr.datasets.synthetic.make_scene` + Gaussian noise σ = 5 + holes):

* ``fast``, ``default``, ``best`` — the speed tiers (``DepthRestorer.from_preset(name)``), and ``full``, the frozen
  configuration's defaults (the default tier until 2026-12-04; ``full-fast`` is the former name of ``fast``), with
  the per-stage split the model reports in ``info["seconds"]`` (block matching, singular detection, nonlocal terms, CG solves, the edge steps, the
  refiner, the rest = total − those) and the CG iterations of every layer;
* ``stream``, ``stream-fast``, ``stream-default`` — a :class:`~torch_depth_sr.StreamRestorer` step of ``full``,
  ``denoise-fast`` and the ``default`` tier on the inputs' static scene (new noise each frame), and
  ``stream-fast-moving``, ``stream-default-moving`` — a step of ``denoise-fast`` and of the ``default`` tier on the
  stream track's moving sensor sequences (movers, flying pixels: the edge steps run), each with its step ÷ a cold
  frame of the same model on the same frames;
* ``jbf`` and ``dictionary`` — the baselines with the parameters of ``evaluation/methods.py``;
* ``kornia-jbf9`` — :func:`kornia.filters.joint_bilateral_blur` with a 9×9 kernel, the outside
  reference every ratio is taken against (``ratio = method time / kornia-jbf9 time``, same size and
  batch, same run). Where ``full`` ran too, each row also gives its time over ``full``'s (``x full``): a ratio
  between two computations of the same kind, which moves less from run to run than the one to kornia's filter.

Each measurement is one warm-up call (a stream's: its cold first frame and ``STREAM_WARM_STEPS`` steps) then the
median of ``repeats`` timed calls. A stream row then times ``repeats`` rounds of steps and cold frames of the same
model in turn (``row["paired"]``, the table's ``step/cold``: the median of the rounds' ratios). By default every
(method, size, batch) runs in its own fresh Python subprocess, so that its peak memory is honest:
the child builds its inputs, resets the kernel's peak-RSS counter (``/proc/self/clear_refs`` ← 5),
runs, and reports ``VmHWM − VmRSS`` at the reset, i.e. the peak resident memory the method added on
top of its inputs (all allocators: torch, numpy, OpenCV, the numba kernels). Where the reset is not
possible the absolute ``VmHWM`` is reported (``peak_kind = "process"``). On CUDA the figure is
``torch.cuda.max_memory_allocated``.

Options are read from ``args`` (the CLI namespace) with defaults when absent, or from environment
variables: ``sizes`` / ``TORCH_DEPTH_SR_SPEED_SIZES`` ("HxW,HxW", e.g. "48x64"), ``batches`` /
``..._BATCHES`` ("1,8"), ``repeats`` / ``..._REPEATS``, ``methods`` (list), ``isolate`` (subprocess per
measurement, default True), ``threads`` / ``..._THREADS``, ``max_seconds`` (a method whose warm-up
took longer than this is not repeated; its warm-up time is reported with ``repeats = 0``),
``skip`` ("method@HxWxB" entries not to run; default skips batch 8 at 1088×1376 for the model methods (``full``,
``fast``, ``best``, ``full-fast`` and the stream rows) and ``dictionary``, too slow on a 2-core CPU).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Optional

import numpy as np
import torch

from ..errors import UsageError
from ..model import named_model

__all__ = [
    "METHODS",
    "SIZES",
    "BATCHES",
    "DEFAULT_SKIP",
    "STAGES",
    "make_inputs",
    "measure_dataloader",
    "measure",
    "run_speed",
]

METHODS = ("full", "fast", "default", "best", "full-fast", "stream", "stream-fast", "stream-fast-moving", "stream-default",
           "stream-default-moving", "bm-exact", "bm-refine", "x0-filter", "jbf", "dictionary", "kornia-jbf9",
           "dataloader")
# the model methods and the named model each runs (DepthRestorer.from_preset): the speed tiers fast / default / best,
# and "full", the frozen configuration's defaults (the default tier until 2026-12-04)
MODEL_PRESETS = {"full": "full", "fast": "fast", "default": "default", "best": "best", "full-fast": "fast"}
# "stream", "stream-fast": a step of a StreamRestorer of the frozen full / of the stream's own model (``denoise-fast``,
# the fast tier until 2026-12-05: stream.DEFAULT_STREAM_MODEL) on the inputs' static scene
# with new noise (σ = 5) and the same holes every call (the warm-up calls are the stream's first, cold, frame and
# STREAM_WARM_STEPS steps; the timed calls are later steps; the rmse is the last step's). A stream runs for thousands
# of frames, and the timed steps are its steady state: its first steps allocate the state and new buffers (on a
# 1376×1088 frame the first step took 3.0 s and the later ones 1.5–2.1), and a static pixel takes the stream's fewer
# layers (StreamConfig.layers, the fast tier's 1) only once its run has its full mean, max_frames (8) frames. The
# warm-up steps' times are kept in the row (warmup_steps_seconds).
STREAM_WARM_STEPS = 8
# a stream row also times its step against a cold frame of the same model in turn, on the same machine load: after
# its own timed steps (whose peak memory the row reports), ``repeats`` rounds of two steps then two cold calls, the
# second of each timed (row["paired"]: the medians and the median of the rounds' ratios, the figure of issue 28's
# step target). Three calls of each in separate processes, minutes apart, gave 53-71 % on this shared 2-core machine
# in two runs; timing the first call after the other kind made a 1376x1088 step 15 % slower than back to back.
STREAM_MODELS = {"stream": "full", "stream-fast": "denoise-fast",  # a preset or a shipped model (from_pretrained)
                 "stream-fast-moving": "denoise-fast", "stream-default": "default",
                 "stream-default-moving": "default"}
MOVING_STREAMS = ("stream-fast-moving", "stream-default-moving")
# "stream-fast-moving", "stream-default-moving": the stream track's evaluated sequences
# (datasets.sequences.STREAM_SEQUENCES, then the tuning ones, one per sample of the batch) at the row's size: movers,
# flying pixels, holes, the frames of a sensor. The static rows' inputs have no flying pixels, so their frames skip
# the edge steps that a sensor's take, streamed or not (docs/measurements/h100-2026-12-05). Each call is the next
# frame; its paired cold frames run on the frame its step took, and its rmse is against that frame's ground truth.
# stages of the model timed alone on the model's own inputs (default config): one exact block-matching pass,
# one re-matching pass by refine_matches (previous matches + a step-2 lattice), the colour-guided x⁰ filter.
# "dataloader" runs examples/restore_in_dataloader.py (2 workers, 320×240, the fast tier) once and reports its
# frames/s.
SIZES = ((370, 463), (480, 640), (1088, 1376))  # (H, W): Middlebury third size, VGA, Middlebury half size
BATCHES = (1, 8)
DEFAULT_SKIP = ("full@1088x1376x8", "fast@1088x1376x8", "default@1088x1376x8", "best@1088x1376x8",
                "full-fast@1088x1376x8", "stream@1088x1376x8", "stream-fast@1088x1376x8",
                "stream-fast-moving@1088x1376x8", "stream-default@1088x1376x8",
                "stream-default-moving@1088x1376x8", "dictionary@1088x1376x8")
STAGES = ("block_matching", "singular", "nonlocal", "cg")
POST_STAGES = ("snap", "refine")  # the edge steps and the edge refiner (row["post_stages"])


# ----------------------------------------------------------------------------------------------
# inputs and methods
# ----------------------------------------------------------------------------------------------


def make_inputs(height: int, width: int, batch: int, seed: int = 0, sigma: float = 5.0, hole_fraction: float = 0.05
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(depth (B,1,H,W) with 0 = hole, rgb (B,3,H,W), gt (B,1,H,W))`` from synthetic scenes."""
    from ..datasets.synthetic import make_scene

    g = torch.Generator().manual_seed(seed)
    ys, rgbs, gts = [], [], []
    for i in range(batch):
        s = make_scene(height, width, seed=seed + i)
        gt = s["gt"]  # (1, H, W)
        y = gt + sigma * torch.randn(gt.shape, generator=g)
        holes = torch.rand(gt.shape, generator=g) < hole_fraction / 2  # scattered dropouts
        hh, ww = max(2, height // 12), max(2, width // 12)  # plus a few rectangular holes
        for _ in range(3):
            r0 = int(torch.randint(0, height - hh, (1,), generator=g))
            c0 = int(torch.randint(0, width - ww, (1,), generator=g))
            holes[:, r0:r0 + hh // 2, c0:c0 + ww] = True
        ys.append(torch.where(holes, torch.zeros_like(y), y.clamp_min(1.0)))
        rgbs.append(s["rgb"])
        gts.append(gt)
    return torch.stack(ys), torch.stack(rgbs), torch.stack(gts)


def _model_runner(model):
    """``(depth, rgb) -> (out, details)`` of ``model``, its stages timed."""

    def run(y, rgb):
        r = model.restore_with_details(y, rgb, timings=True)
        return r.depth, r.info

    return run


def _make_runner(method: str, device: str, frames: int = 0):
    """A function ``(depth, rgb) -> (out, details or None)`` for ``method`` (``frames``: how many calls a moving
    stream's frames must cover)."""
    from .methods import DICTIONARY_PARAMS, JBF_PARAMS

    if method in MODEL_PRESETS:
        return _model_runner(named_model(MODEL_PRESETS[method]).to(device))
    if method in MOVING_STREAMS:
        return _moving_stream_runner(STREAM_MODELS[method], device, frames)
    if method in STREAM_MODELS:
        from ..stream import StreamRestorer

        stream = StreamRestorer(named_model(STREAM_MODELS[method]).to(device))
        g = torch.Generator(device="cpu").manual_seed(1)
        scene: dict = {}

        def step(y, rgb):
            if "gt" not in scene:  # the inputs' scene (make_inputs' defaults): each call a new frame of its noise
                _, _, gt = make_inputs(y.shape[-2], y.shape[-1], y.shape[0])
                scene.update(gt=gt.to(y), holes=y <= 0)
            noise = (5.0 * torch.randn(y.shape, generator=g)).to(y)
            frame = torch.where(scene["holes"], torch.zeros_like(y), (scene["gt"] + noise).clamp_min(1.0))
            r = stream.step(frame, rgb, return_details=True, timings=True)
            return r.depth, r.info

        return step
    if method in ("bm-exact", "bm-refine", "x0-filter"):
        return _stage_runner(method)
    if method == "jbf":
        from ..baselines import joint_bilateral_filter

        return lambda y, rgb: (joint_bilateral_filter(y, rgb, (y > 0).to(y.dtype), **JBF_PARAMS), None)
    if method == "dictionary":
        from ..baselines import dictionary_denoise

        return lambda y, rgb: (dictionary_denoise(y, rgb, (y > 0).to(y.dtype), **DICTIONARY_PARAMS), None)
    if method == "kornia-jbf9":
        import kornia

        return lambda y, rgb: (kornia.filters.joint_bilateral_blur(y, rgb, (9, 9), 0.1, (3.0, 3.0)), None)
    raise ValueError(f"unknown speed method {method!r}; allowed are {list(METHODS)}.")


def _moving_stream_runner(model: str, device: str, frames: int):
    """``stream-fast-moving``, ``stream-default-moving``: each call steps a :class:`~torch_depth_sr.StreamRestorer` of
    ``model`` (a preset or a shipped model) to the next frame of the moving sequences (the inputs it is given only
    tell the size and batch); ``step.frame`` is the frame it last took and ``step.gt`` its ground truth."""
    from ..datasets.sequences import STREAM_SEQUENCES, TUNING_SEQUENCES, make_sequence
    from ..stream import StreamRestorer

    stream = StreamRestorer(named_model(model).to(device))
    specs = [*STREAM_SEQUENCES, *TUNING_SEQUENCES]
    cache: dict = {}

    def step(y, rgb):
        if "depth" not in cache:
            seqs = [make_sequence(specs[i % len(specs)], frames=max(frames, 2), height=y.shape[-2], width=y.shape[-1])
                    for i in range(y.shape[0])]
            cache.update({k: torch.from_numpy(np.stack([q[k] for q in seqs], 1).astype(np.float32)).to(y.device)
                          for k in ("depth", "gt", "rgb")})
            cache["t"] = 0
        t = min(cache["t"], cache["depth"].shape[0] - 1)  # past the last frame: the last again (a still scene)
        cache["t"] += 1
        step.frame, step.gt = (cache["depth"][t], cache["rgb"][t]), cache["gt"][t]
        r = stream.step(*step.frame, return_details=True, timings=True)
        return r.depth, r.info

    return step


def _stage_runner(method: str):
    """One stage of the model alone, on normalised inputs as the model builds them (default config)."""
    from ..block_matching import block_match, refine_matches
    from ..fill import fill_holes
    from ..initial import initial_estimate
    from ..model import DepthRestorer

    model = DepthRestorer()
    c, bm = model.config, model.config.block_matching
    kw = dict(block_size=bm.block_size, search_window=bm.search_window, k=bm.k,
              color_weight=float(model.block_matcher.color_weight), temperature=float(model.block_matcher.temperature))
    cache: dict = {}

    def normalised(y):
        observed = (y > 0).to(y.dtype)
        yn = y / 5.0  # the inputs' noise σ is 5: the model's units
        return yn, observed

    def run(y, rgb):
        yn, observed = normalised(y)
        if method == "x0-filter":
            return initial_estimate(yn, observed, rgb, 1, c.initial, c.sided_fill), None
        key = (y.data_ptr(), tuple(y.shape))
        if key not in cache:  # the estimate the passes match on, and a first pass for refine to start from
            x = fill_holes(yn, observed)
            cache[key] = (x, block_match(x, rgb, observed, **kw))
        x, first = cache[key]
        if method == "bm-exact":
            return block_match(x, rgb, observed, **kw).dist, None
        return refine_matches(x, first, rgb, observed, **kw, reach=0, lattice=2).dist, None

    return run


def measure_dataloader(workers: int = 2, frames: int = 16, size: tuple[int, int] = (240, 320),
                       tier: str = "fast") -> dict:
    """Frames per second of ``examples/restore_in_dataloader.py --tier TIER`` (start-up included), or an error
    row."""
    script = Path(__file__).resolve().parents[2] / "examples" / "restore_in_dataloader.py"
    row = {"method": "dataloader", "height": size[0], "width": size[1], "batch": 1, "workers": workers,
           "frames": frames, "tier": tier}
    if not script.exists():
        return {**row, "error": f"{script} not found (the examples ship with the repository, not the wheel)"}
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, str(script), "--workers", str(workers), "--frames", str(frames), "--size",
                        str(size[0]), str(size[1]), "--tier", tier], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    for line in p.stdout.splitlines():
        if "frames/s" in line:
            fps = float(line.split("frames/s")[0].split()[-1])
            return {**row, "fps": fps, "seconds": 1.0 / fps, "wall_seconds": wall, "line": line.strip()}
    return {**row, "error": (p.stderr or p.stdout)[-2000:]}


def _sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def _proc_status(field: str) -> Optional[float]:
    """A ``/proc/self/status`` field in MB (Linux), else None."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return None


def _reset_peak() -> bool:
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def measure(method: str, height: int, width: int, batch: int, device: str = "cpu", repeats: int = 3,
            max_seconds: float = 120.0, threads: Optional[int] = None) -> dict:
    """One measurement in this process: warm-up, ``repeats`` timed calls, peak memory, stage split."""
    if threads:
        torch.set_num_threads(int(threads))
    y, rgb, gt = make_inputs(height, width, batch)
    y, rgb = y.to(device), rgb.to(device)
    run = _make_runner(method, device, frames=1 + STREAM_WARM_STEPS + 3 * repeats)
    cuda = device.startswith("cuda")
    if cuda:
        torch.cuda.reset_peak_memory_stats()
        base = torch.cuda.memory_allocated()
    else:
        base = _proc_status("VmRSS")
        reset = _reset_peak()
    times, infos = [], []
    with torch.no_grad():
        t0 = time.perf_counter()
        out, info = run(y, rgb)
        _sync(device)
        warm = time.perf_counter() - t0
        n = repeats if warm <= max_seconds else 0
        warm_steps = []
        for _ in range(STREAM_WARM_STEPS if method in STREAM_MODELS and n else 0):
            t0 = time.perf_counter()
            run(y, rgb)
            _sync(device)
            warm_steps.append(time.perf_counter() - t0)
        for _ in range(n):
            t0 = time.perf_counter()
            out, info = run(y, rgb)
            _sync(device)
            times.append(time.perf_counter() - t0)
            infos.append(info)
        # the stream's own peak, before the paired cold frames
        peak = torch.cuda.max_memory_allocated() if cuda else _proc_status("VmHWM")
        paired = _paired_rounds(method, run, y, rgb, device, n) if method in STREAM_MODELS and n else None
    row = {"method": method, "height": height, "width": width, "batch": batch, "repeats": len(times),
           "seconds": statistics.median(times) if times else warm, "seconds_all": times, "warmup_seconds": warm}
    if warm_steps:
        row["warmup_steps_seconds"] = warm_steps
    if paired:
        row["paired"] = paired
    if cuda:
        row["peak_mb"] = (peak - base) / 2**20
        row["peak_kind"] = "cuda_allocated_over_inputs"
    else:
        hwm = peak
        if reset and hwm is not None and base is not None:
            row["peak_mb"], row["peak_kind"] = max(0.0, hwm - base), "rss_over_inputs"
        else:
            row["peak_mb"], row["peak_kind"] = hwm, "process"
    if info is not None:  # the model: stage split of the median run, CG iterations per layer
        infos = infos or [info]
        med = sorted(infos, key=lambda d: d["seconds"]["total"])[len(infos) // 2]
        sec = dict(med["seconds"])
        sec["rest"] = sec["total"] - sum(sec.get(k, 0.0) for k in (*STAGES, *POST_STAGES))
        row["stages"] = {k: sec.get(k, 0.0) for k in (*STAGES, "rest", "total")}
        row["post_stages"] = {k: sec.get(k, 0.0) for k in POST_STAGES}
        row["cg_iterations"] = list(med["cg_iterations"])
        truth = getattr(run, "gt", gt)  # a moving stream's: the frame it took
        row["rmse"] = float((out.float().cpu() - truth.float().cpu()).pow(2).mean().sqrt())
    row["threads"] = torch.get_num_threads()
    row["loadavg"] = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    return row


def _paired_rounds(method: str, step, y: torch.Tensor, rgb: torch.Tensor, device: str, rounds: int) -> dict:
    """``rounds`` rounds of two stream steps then two cold frames of the same model (``STREAM_MODELS``), the second
    of each timed: ``{"step", "cold"}`` medians (s) and ``"ratio"``, the median of the rounds' step / cold."""
    model_run = _model_runner(named_model(STREAM_MODELS[method]).to(device))
    # a moving stream's cold frames restore the frame its step last took; the others the row's inputs
    cold = (lambda y, rgb: model_run(*step.frame)) if hasattr(step, "frame") else model_run
    cold(y, rgb)  # its warm-up
    _sync(device)
    steps, colds = [], []
    for _ in range(rounds):
        for run, into in ((step, steps), (cold, colds)):
            run(y, rgb)  # untimed: the first call after the other kind faults its freed pages in again (glibc
            _sync(device)  # returns them to the system), which a stream's back-to-back steps do not
            t0 = time.perf_counter()
            run(y, rgb)
            _sync(device)
            into.append(time.perf_counter() - t0)
    return {"step": statistics.median(steps), "cold": statistics.median(colds),
            "ratio": statistics.median(a / b for a, b in zip(steps, colds)), "steps": steps, "colds": colds}


def _measure_isolated(method, h, w, b, device, repeats, max_seconds, threads) -> dict:
    code = ("import json,sys; from torch_depth_sr.evaluation.speed import measure; "
            "print('@@' + json.dumps(measure(*json.loads(sys.argv[1]))))")
    arg = json.dumps([method, h, w, b, device, repeats, max_seconds, threads])
    p = subprocess.run([sys.executable, "-c", code, arg], capture_output=True, text=True)
    for line in p.stdout.splitlines():
        if line.startswith("@@"):
            return json.loads(line[2:])
    return {"method": method, "height": h, "width": w, "batch": b, "error": (p.stderr or p.stdout)[-2000:]}


# ----------------------------------------------------------------------------------------------
# the benchmark
# ----------------------------------------------------------------------------------------------


def _option(args, name: str, env: str, default, parse):
    v = getattr(args, name, None)
    if v is None:
        v = os.environ.get(env)
    if v is None or v == "":
        return default
    return parse(v) if isinstance(v, str) else v


def _parse_sizes(s: str):
    return tuple(tuple(int(t) for t in part.lower().split("x")) for part in s.split(",") if part.strip())


def _parse_ints(s: str):
    return tuple(int(t) for t in s.split(",") if t.strip())


def run_speed(args: argparse.Namespace) -> int:
    """Run the speed track; print a table; write ``{"metadata", "results"}`` JSON to ``args.json``."""
    from .report import metadata as _metadata, print_table as _print_table

    device = getattr(args, "device", None) or "cpu"
    sizes = _option(args, "sizes", "TORCH_DEPTH_SR_SPEED_SIZES", SIZES, _parse_sizes)
    batches = _option(args, "batches", "TORCH_DEPTH_SR_SPEED_BATCHES", BATCHES, _parse_ints)
    repeats = int(_option(args, "repeats", "TORCH_DEPTH_SR_SPEED_REPEATS", 3, int))
    threads = _option(args, "threads", "TORCH_DEPTH_SR_SPEED_THREADS", None, int)
    max_seconds = float(_option(args, "max_seconds", "TORCH_DEPTH_SR_SPEED_MAX_SECONDS", 120.0, float))
    skip = set(_option(args, "skip", "TORCH_DEPTH_SR_SPEED_SKIP", DEFAULT_SKIP, lambda s: s.split(",")))
    isolate = bool(getattr(args, "isolate", True))
    methods = [m for m in (getattr(args, "methods", None) or METHODS)]
    if "kornia-jbf9" not in methods:
        methods.append("kornia-jbf9")  # the reference of every ratio
    for m in methods:
        if m not in METHODS:
            raise UsageError(f"unknown speed method {m!r}; allowed are {list(METHODS)}.")
    results, skipped = [], []
    if "dataloader" in methods:
        methods.remove("dataloader")
        row = measure_dataloader()
        results.append(row)
        print(f"  dataloader (2 workers, 320x240, tier {row['tier']}): " + (f"{row['fps']:.2f} frames/s" if "fps" in row
                                                       else "ERROR " + row["error"]), flush=True)
    for h, w in sizes:
        for b in batches:
            for m in methods:
                tag = f"{m}@{h}x{w}x{b}"
                if tag in skip:
                    skipped.append(tag)
                    continue
                if isolate:
                    row = _measure_isolated(m, h, w, b, device, repeats, max_seconds, threads)
                else:
                    row = measure(m, h, w, b, device, repeats, max_seconds, threads)
                results.append(row)
                print(f"  {tag}: " + (f"{row['seconds']:.3f} s" if "seconds" in row else "ERROR " + row["error"]),
                      flush=True)
    ref = {(r["height"], r["width"], r["batch"]): r["seconds"] for r in results
           if r["method"] == "kornia-jbf9" and "seconds" in r}
    # the frozen full model as a second reference: its time moves with the machine as the tiers' do, while kornia's
    # filter is mostly memory traffic (about 100 MB of temporaries a call) and swings 2x between runs
    full = {(r["height"], r["width"], r["batch"]): r["seconds"] for r in results
            if r["method"] == "full" and "seconds" in r}
    table = []
    for r in results:
        if "seconds" not in r:
            continue
        if r["method"] == "dataloader":
            table.append({"method": f"dataloader, {r.get('tier', 'default')}, {r['workers']} workers "
                                    f"(frames/s {r['fps']:.2f})",
                          "size": f"{r['width']}x{r['height']}", "batch": 1, "seconds": r["seconds"],
                          "ms/frame": 1000.0 * r["seconds"]})
            continue
        k = ref.get((r["height"], r["width"], r["batch"]))
        r["ratio_to_kornia_jbf9"] = r["seconds"] / k if k else None
        f = full.get((r["height"], r["width"], r["batch"]))
        r["ratio_to_full"] = r["seconds"] / f if f else None
        r["ms_per_frame"] = 1000.0 * r["seconds"] / r["batch"]
        t = {"method": r["method"], "size": f"{r['width']}x{r['height']}", "batch": r["batch"],
             "seconds": r["seconds"], "ms/frame": r["ms_per_frame"], "x kornia9": r["ratio_to_kornia_jbf9"],
             "x full": r["ratio_to_full"],
             "peak MB": r.get("peak_mb"), "load": r["loadavg"][0] if r.get("loadavg") else None}
        st = r.get("stages")
        if st:
            t.update({"bm": st["block_matching"], "singular": st["singular"], "nonlocal": st["nonlocal"], "cg": st["cg"],
                      "edges": r.get("post_stages", {}).get("snap", 0.0),
                      "refiner": r.get("post_stages", {}).get("refine", 0.0), "rest": st["rest"],
                      "cg it/layer": "/".join(str(i) for i in r["cg_iterations"])})
        if r.get("paired"):
            t["step/cold"] = r["paired"]["ratio"]
        table.append(t)
    cols = ["method", "size", "batch", "seconds", "ms/frame", "x kornia9", "x full", "peak MB", "bm", "singular",
            "nonlocal", "cg", "edges", "refiner", "rest", "cg it/layer", "step/cold", "load"]
    meta = _metadata(device)
    meta.update(track="speed", threads=threads or torch.get_num_threads(), cpu_count=os.cpu_count(),
                sizes=[list(s) for s in sizes], batches=list(batches), repeats=repeats, isolated=isolate,
                skipped=skipped, loadavg_end=list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
                memory="peak RSS added over the inputs, fresh subprocess per row (VmHWM after clear_refs)"
                if isolate else "peak RSS added over the inputs in this process (VmHWM after clear_refs)",
                inputs="make_scene + Gaussian noise sigma=5 + ~5% holes (2.5% dropouts, 3 rectangles)")
    try:
        import cv2
        import numpy

        meta.update(opencv=cv2.__version__, numpy=numpy.__version__, torch_threads=torch.get_num_threads())
    except ImportError:  # pragma: no cover - both are dependencies
        pass
    networks = meta.get("network_precision") or f"auto: {meta.get('auto_networks')} here"
    _print_table(table, cols, f"track speed on {device}, {meta['threads']} thread(s); median of {repeats} "
                 f"after a warm-up; the models' networks in {networks}; 'x kornia9' = time / kornia "
                 f"joint_bilateral_blur 9x9, 'x full' = time / the frozen full model (same size, batch, run; full "
                 f"where it ran)")
    if skipped:
        print("skipped (too slow here): " + ", ".join(skipped))
    if getattr(args, "json", None):
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"metadata": meta, "results": results}, indent=1))
        print(f"json: {args.json}")
    return 0
