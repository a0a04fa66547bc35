"""``torch-depth-sr warmup``: compile every numba CPU kernel the forward can call into numba's on-disk cache ahead
of the first forward (``make install`` runs it). The kernels and their loading live in :mod:`torch_depth_sr.native`;
this module runs each kernel once on a small input, as the forward calls it."""
from __future__ import annotations

import time
from typing import Callable, Optional, Sequence

import torch

from .block_matching import block_match
from .block_matching.refine import refine_matches
from .config import StreamConfig
from .edge_snap import refit_to_measurements, snap_to_sides
from .fill import fill_holes_sided
from .guided_filters import domain_transform_filter
from .native import _NOTICE, _dispatchers, _ours, cpu_kernel, kernel_cache_dir
from .nonlocal_prior import nonlocal_gradient, nonlocal_terms
from .operators import grad
from .singular import detect_singular, supported_or_line
from .stream.change import _nearest_distance as nearest_distance
from .stream.change import camera_moved, colour_changes, depth_votes, local_spread, remembered_spread
from .stream.shift import shifted_windows
from .stream.runs import grow_runs, join_runs
from .window_max import dilate

__all__ = ["warmup"]


def _warmup_steps(dtype: torch.dtype):
    """``(label, call)``: each kernel wrapper on a small synthetic input, as the forward calls it (the wrappers cast
    and copy their inputs to C-contiguous float32/float64 arrays, so these are every signature they compile)."""
    g = torch.Generator().manual_seed(0)
    x = torch.rand(1, 1, 16, 20, generator=g, dtype=dtype)
    rgb = torch.rand(1, 3, 16, 20, generator=g, dtype=dtype)
    trust = (torch.rand(1, 1, 16, 20, generator=g) > 0.1).to(dtype)
    kw = dict(block_size=3, search_window=7, k=4)
    held = {}

    def matching():
        held["m"] = block_match(x, rgb, trust, **kw, backend="numba")

    def rematching():  # the re-ranking: a small window's by the exact search kept to the candidates, a larger one's
        # (the best tier's 21×21) candidate by candidate, then the lattice search seeded with them
        refine_matches(x, held["m"], rgb, None, **kw, reach=1, lattice=2)
        wide = dict(kw, search_window=11)
        refine_matches(x, block_match(x, rgb, trust, **wide, backend="numba"), rgb, trust, **wide, lattice=2)

    def terms():
        with torch.no_grad():
            nonlocal_terms(x, grad(x), held["m"], value_weight=1.0, plane_ridge=0.1, range_sigma=1.0)
            nonlocal_gradient(grad(x), held["m"])  # x⁰'s α⁰ alone

    def singular():  # the test's rounds and its support rule (neighbours and lines)
        detect_singular(x, x, trust, held["m"], sigma_floor=0.1, rounds=2, backend="numba")
        supported_or_line(10 * x, trust, 0.5, 3)

    def edges():  # both edge steps as the model calls them (no gradient; the refit finds edge pixels in 10·x)
        with torch.no_grad():
            snap_to_sides(x, rgb, rounds=1, radius=2, sigma_space=1.5)
            refit_to_measurements(10 * x, 10 * x, trust, rgb, radius=2)

    def hole_fill():  # holes of 2×2 and more than 512 of them: the pass runs on the calling thread and on two
        hole = torch.zeros(2, 1, 40, 40, dtype=torch.bool)
        hole[..., 1::3, :] = True
        hole[..., 2::3, ::2] = True
        depth = torch.rand(2, 1, 40, 40, generator=g, dtype=dtype) * 10
        with torch.no_grad():
            fill_holes_sided(depth, (~hole).to(dtype), torch.rand(1, 3, 40, 40, generator=g, dtype=dtype),
                             kernel_size=7, choice_sigma_space=1.5)

    def domain():  # x⁰'s colour-guided filter: its row and column boxes (in float64, whatever the dtype)
        with torch.no_grad():
            domain_transform_filter(x, rgb, trust)

    def stream_means():  # a stream's window means (its change test and state), in the frames' dtype
        with torch.no_grad():
            local_spread(x, trust, x, 3)
            remembered_spread(x, trust, x, x.flip(-1), x, x > 0.5, 3, 0.9)

    def stream_change():  # the change test's nearest distances (noise per pixel and per sample), votes, dilation
        with torch.no_grad():
            for noise in (x + 1, torch.ones(1, 1, 1, 1, dtype=dtype)):
                nearest_distance(x, trust, x.flip(-1), noise)
            dilate(x > 0.5, 2)
            depth_votes(x, trust, 3, 0.5)
            colour_changes(rgb, rgb.flip(-1), 3, 0.03)
            camera_moved(rgb, rgb.flip(-1))
            shifted_windows(10 * x, trust, 10 * x.roll(1, -1), x + 0.5, 0.5)

    def stream_runs():  # a stream's run updates before and after the model
        s, b, one = StreamConfig(), x > 0.5, torch.ones(1, dtype=dtype)
        with torch.no_grad():
            j = join_runs(x, trust, b, b, x + 1, x, x, x, x, one, one, s)
            grow_runs(j.y, j.observed, b, x, b, j.restarted, x, x, x, x, one, one, s)

    return [("block matching", matching), ("re-matching", rematching), ("nonlocal terms", terms),
            ("singular test", singular), ("edge steps", edges), ("hole fill", hole_fill), ("x0 filter", domain),
            ("stream means", stream_means), ("stream change test", stream_change), ("stream runs", stream_runs)]


def _model_steps(model: torch.nn.Module, dtype: torch.dtype):
    """``(label, call)``: one denoising forward of ``model`` on a small synthetic sensor frame in ``dtype``."""
    from .datasets.synthetic import make_scene
    from .degradations import SensorDegradation

    frame = SensorDegradation(seed=0)(make_scene(48, 64, seed=0))

    def forward():
        with torch.no_grad():
            model(frame["depth"][None].to(dtype), frame["rgb"][None].to(dtype))

    return [("model forward", forward)]


def warmup(dtypes: Sequence[torch.dtype] = (torch.float32, torch.float64),
           log: Optional[Callable[[str], None]] = None, model: Optional[torch.nn.Module] = None) -> dict:
    """Compile every numba CPU kernel the forward can call, for each dtype, into numba's on-disk cache (or load it
    from there when an earlier run did): after it a forward compiles nothing. Idempotent; a second run only loads.

    Each kernel runs once on a small input with one thread (the serial paths) and with two (the parallel paths;
    one where numba has a single thread). ``log`` receives one line per step.

    With ``model`` (a :class:`~torch_depth_sr.DepthRestorer`), only the kernels that model's denoising forward calls
    are compiled or loaded, for each dtype: it runs once, without gradient, on a small synthetic sensor frame (holes,
    flying pixels, depth edges). For a DataLoader's main process before its workers fork: they inherit what is
    loaded, and a model that calls a few of the kernels loads only those (``examples/restore_in_dataloader.py``).

    Returns:
        ``{"compiled": n, "loaded": n, "seconds": s, "cache": path, "steps": [(dtype, label, compiled, loaded, s),
        ...]}``: the kernel signatures compiled now and those loaded from the cache (numba's helpers not counted).

    Raises:
        DepthSRError: numba is missing, broken or turned off (``TORCH_DEPTH_SR_NO_NUMBA``).
    """
    cpu_kernel("singular_kernel", "singular_rounds_cpu", required=True)  # numba importable and enabled, or raise
    from numba.core import event

    class _Count(event.Listener):
        n = 0

        def on_start(self, ev):
            if _ours(ev):
                _Count.n += 1

        def on_end(self, ev):
            pass

    disp = _dispatchers()

    def loaded() -> int:
        return sum(sum(d.stats.cache_hits.values()) for d in disp.values())

    threads = torch.get_num_threads()
    steps = []
    t0, hits0 = time.perf_counter(), loaded()
    _NOTICE["quiet"] = True
    try:
        with event.install_listener("numba:compile", _Count()):
            for dt in dtypes:
                for label, call in (_warmup_steps(dt) if model is None else _model_steps(model, dt)):
                    n0, h0, s0 = _Count.n, loaded(), time.perf_counter()
                    for n in (max(2, threads), 1):
                        torch.set_num_threads(n)
                        call()
                    st = (str(dt).replace("torch.", ""), label, _Count.n - n0, loaded() - h0, time.perf_counter() - s0)
                    steps.append(st)
                    if log is not None:
                        what = [f"compiled {st[2]}"] if st[2] else []
                        what += [f"loaded {st[3]} from the cache"] if st[3] else []
                        log(f"{st[0]:<8} {st[1]:<15} {st[4]:6.1f} s  "
                            + (", ".join(what) if what else "already compiled in this process"))
    finally:
        _NOTICE["quiet"] = False
        torch.set_num_threads(threads)
    return {"compiled": _Count.n, "loaded": loaded() - hits0, "seconds": time.perf_counter() - t0,
            "cache": kernel_cache_dir(), "steps": steps}
