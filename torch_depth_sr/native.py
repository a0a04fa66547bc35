"""The one loader of the compiled CPU kernels (numba): block matching, the singular test, the nonlocal terms, the
edge steps' medians, the hole fill's passes, the boxes of x⁰'s domain-transform filter, a stream's window means
and change test.

Each kernel module imports numba at its top; :func:`cpu_kernel` imports it on first use and returns the
requested function, or None, so that the caller runs its torch path (same results, slower on a CPU). Without
numba, one warning is given per process, whichever kernel is asked for first. ``TORCH_DEPTH_SR_NO_NUMBA=1``
turns every kernel off, silently.

Threads. Most kernels are serial numba functions that release the GIL (``nogil=True``): :func:`run_tasks` runs
chunks of their work (bands of rows, chunks of pixels) on ``torch.get_num_threads()`` threads of a Python thread
pool, with the same results for any thread count. They used to be ``parallel=True`` kernels (``numba.prange``),
which compile 2 to 3 times longer: numba compiles the loop body again as a separate function and re-optimises
every callee linked into it (the exact block matching took 12.0 s of CPU to compile instead of 4.7 s,
docs/measurements/numba-first-use/). The re-matching's kernel stays a ``prange`` loop, which runs it faster. numba's
parallel loops run on its ``workqueue`` threading layer unless ``NUMBA_THREADING_LAYER`` says otherwise: its
default, OpenMP, is a second OpenMP runtime beside torch's, and the idle threads of the two spin against each
other (a forward at 640×480 took 6.8 s with OpenMP and 5.6 s with workqueue on this 2-core machine with one busy
background process).

Compilation. numba compiles a kernel for each dtype (float32, float64) at its first call and caches the machine
code on disk (``cache=True``: ``__pycache__`` beside the kernel modules, or ``NUMBA_CACHE_DIR``); later processes
load it in well under a second. With an empty cache the first float32 forward compiles for 10-12 s of CPU (26 s
before most kernels left ``prange``; docs/measurements/numba-first-use/). :func:`warmup` (``torch-depth-sr warmup``,
run by ``make install``) does it ahead of time for both dtypes; otherwise the first compilation of a process says
so once, in one line on stderr, through the ``torch_depth_sr`` logger (level WARNING). A logger rather than
:mod:`warnings`: it is a progress notice about a wait, not a fault in the caller's code, so ``-W error`` (or
pytest's ``filterwarnings = error``) must not turn it into an exception raised inside numba's compiler;
``logging.getLogger("torch_depth_sr").setLevel(logging.ERROR)`` silences it.
"""
from __future__ import annotations

import importlib
import itertools
import logging
import os
import threading
import warnings
from typing import Callable, Optional, Sequence

import numpy as np
from numpy.typing import DTypeLike
import torch

from .errors import DepthSRError

__all__ = ["as_numpy", "compiled_signatures", "cpu_kernel", "device_path_forced", "host_path", "kernel_cache_dir",
           "kernel_threads", "numba_disabled", "run_range", "run_tasks"]

_FAILED: Optional[str] = None  # why numba is unavailable, once known
_CONFIGURED = False
_LOG = logging.getLogger("torch_depth_sr")
# the kernel modules (under torch_depth_sr) whose numba functions warmup compiles and the notice watches
KERNEL_MODULES = ("block_matching.cpu_exact", "block_matching.refine_cpu", "dilate_kernel", "domain_kernel",
                  "edge_snap_kernel", "fill_kernel", "nonlocal_kernel", "singular_kernel", "stream.box_kernel",
                  "stream.change_kernel", "stream.matches_kernel", "stream.runs_kernel", "stream.shift_kernel")
COMPILE_SECONDS = 22  # the kernels of a float32 forward: 20-25 s of CPU at 320x240 on this project's 2-core machine
# (docs/measurements/issue27-tiers/fifteenth-stop/first_forward_fresh_cache.txt; 13 s when first measured)
_NOTICE = {"given": False, "quiet": False}  # the first-compile notice: once per process; not during warmup


def numba_disabled() -> bool:
    """Whether ``TORCH_DEPTH_SR_NO_NUMBA`` turns the kernels off."""
    return os.environ.get("TORCH_DEPTH_SR_NO_NUMBA", "") not in ("", "0")


def device_path_forced() -> bool:
    """Whether ``TORCH_DEPTH_SR_DEVICE_PATH`` makes the CPU run the path of the other devices (tests)."""
    return os.environ.get("TORCH_DEPTH_SR_DEVICE_PATH", "") not in ("", "0")


def host_path(device: torch.device) -> bool:
    """Whether work on ``device`` takes the CPU path: the numba kernels, and the shortcuts that read a tensor's
    values on the host to skip work (free on the CPU; on a GPU each would make the host wait for the device). Every
    other device takes the device path: torch kernels, no host synchronisation, the same values.
    ``TORCH_DEPTH_SR_DEVICE_PATH=1`` sends the CPU down the device path too, so that tests check it without a GPU."""
    return device.type == "cpu" and not device_path_forced()


def host_kernel(module: str, name: str, *tensors: torch.Tensor,
                dtypes: Optional[Sequence[torch.dtype]] = (torch.float32, torch.float64)) -> Optional[Callable]:
    """The numba kernel ``torch_depth_sr.<module>.<name>`` (:func:`cpu_kernel`) for work on ``tensors``, when it may
    run: the first tensor on the host path (:func:`host_path`), each of one of ``dtypes`` (None: any), and no
    gradient asked of any of them. Else None, as without numba: the caller takes its torch path. The one gate of
    the kernels that keep the torch path's values; pass ``t.detach()`` for an input whose result carries no
    gradient anyway (integer box ends, block matches)."""
    if not tensors or not host_path(tensors[0].device):
        return None
    if dtypes is not None and any(t.dtype not in dtypes for t in tensors):
        return None
    if torch.is_grad_enabled() and any(t.requires_grad for t in tensors):
        return None
    return cpu_kernel(module, name)


def on_device(value, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """``value`` (a Python number, or a tensor) as a tensor of ``dtype`` on ``device``. A number is filled in on the
    device rather than copied from the host: a CUDA graph cannot capture a copy from pageable host memory, which
    ``torch.as_tensor(number, device=...)`` is. The same value as ``as_tensor`` (one rounding to ``dtype``)."""
    if isinstance(value, torch.Tensor):
        return value.to(dtype=dtype, device=device)
    return torch.full((), value, dtype=dtype, device=device)


def _configure_numba() -> None:
    global _CONFIGURED
    if _CONFIGURED:
        return
    import numba

    if "NUMBA_THREADING_LAYER" not in os.environ:
        numba.config.THREADING_LAYER = "workqueue"
    _watch_compiles()
    _CONFIGURED = True


def _ours(event) -> bool:
    """Whether a ``numba:compile`` event compiles one of this package's kernels (not numba's own helpers)."""
    func = getattr((event.data or {}).get("dispatcher"), "py_func", None)
    return getattr(func, "__module__", "").startswith("torch_depth_sr.")


def _watch_compiles() -> None:
    """Give the one-line notice when a kernel of this package is compiled (not loaded from the cache) for the first
    time in this process. numba's event API (``numba.core.event``) reports compilations only, never cache loads."""
    try:
        from numba.core import event
    except ImportError:  # an older numba without the event API: no notice, nothing else changes
        return

    class _FirstCompile(event.Listener):
        def on_start(self, ev):
            if _NOTICE["given"] or _NOTICE["quiet"] or not _ours(ev):
                return
            _NOTICE["given"] = True
            _LOG.warning("torch_depth_sr: compiling the numba CPU kernels on their first use (about %d s per dtype, "
                         "once: later runs load them from numba's cache); `torch-depth-sr warmup` does this ahead "
                         "of time", COMPILE_SECONDS)

        def on_end(self, ev):
            pass

    event.register("numba:compile", _FirstCompile())


def cpu_kernel(module: str, name: str, required: bool = False) -> Optional[Callable]:
    """``torch_depth_sr.<module>.<name>`` (a numba-compiled function's wrapper), or None without numba.

    Args:
        module: the kernel module under ``torch_depth_sr`` (e.g. ``"singular_kernel"``).
        name: the function in it.
        required: raise :class:`~torch_depth_sr.errors.DepthSRError` instead of returning None.
    """
    global _FAILED
    if numba_disabled():
        if required:
            raise DepthSRError("the numba CPU kernels are unavailable: TORCH_DEPTH_SR_NO_NUMBA is set.")
        return None
    if _FAILED is None:
        try:
            _configure_numba()
            return getattr(importlib.import_module(f"torch_depth_sr.{module}"), name)
        except ImportError as exc:  # numba missing, or broken for this numpy/python
            _FAILED = f"numba could not be imported ({exc})"
            if not required:
                warnings.warn(f"torch_depth_sr: {_FAILED}; the CPU kernels (block matching, singular test, "
                              "nonlocal terms, edge steps, hole fill, x⁰ filter, stream window means) fall back to "
                              "the torch path (same results, several times slower). `pip install numba` restores "
                              "the fast path.", RuntimeWarning, stacklevel=3)
    if required:
        raise DepthSRError(f"the numba CPU kernels are unavailable: {_FAILED}. Use backend='auto' or 'torch'.")
    return None


def kernel_threads() -> int:
    """The threads the kernels run on: torch's thread count (``torch.set_num_threads``), capped at numba's
    ``NUMBA_NUM_THREADS`` (the CPU count unless set); also set for numba's parallel loops (the re-matching's). The
    kernels run on the calling thread when it is 1."""
    import numba

    _configure_numba()  # a kernel module imported directly, not through cpu_kernel: the same layer and notice
    n = max(1, min(torch.get_num_threads(), numba.config.NUMBA_NUM_THREADS))
    numba.set_num_threads(n)
    return n


_POOL: dict = {"pool": None, "size": 0, "pid": 0}
_POOL_LOCK = threading.Lock()


def run_tasks(task: Callable[[int], object], count: int) -> list:
    """``[task(0), ..., task(count - 1)]``, run on :func:`kernel_threads` threads (the calling thread and the
    workers of a pool): the kernels are compiled with ``nogil=True``, so tasks that call them run in parallel. Each
    thread takes the next task as soon as it is done with its last. With one thread, all on the calling thread.

    Most kernels parallelise this way rather than by ``parallel=True`` (``numba.prange``) because that compiles them
    two to three times over (numba compiles the loop body as one more function and re-optimises every callee linked
    into it): the exact block matching compiled in 4.7 s of CPU instead of 12.0 s (docs/measurements/
    numba-first-use/). The pool is made again in a forked child (its threads are not inherited) and when the
    thread count changes. A task's exception stops the others taking new tasks and is raised here.
    """
    n = min(kernel_threads(), count)
    if n <= 1:
        return [task(i) for i in range(count)]
    with _POOL_LOCK:
        if _POOL["pool"] is None or _POOL["size"] != n - 1 or _POOL["pid"] != os.getpid():
            from concurrent.futures import ThreadPoolExecutor

            if _POOL["pool"] is not None and _POOL["pid"] == os.getpid():
                _POOL["pool"].shutdown(wait=False)  # tasks already queued still run
            _POOL.update(pool=ThreadPoolExecutor(n - 1, thread_name_prefix="torch_depth_sr"), size=n - 1,
                         pid=os.getpid())
        pool = _POOL["pool"]
    results: list = [None] * count
    ids = itertools.count()  # next() on it is atomic under the GIL
    failed: list = []

    def work() -> None:
        for i in ids:
            if i >= count or failed:
                return
            try:
                results[i] = task(i)
            except BaseException:
                failed.append(i)
                raise

    helpers = [pool.submit(work) for _ in range(n - 1)]
    try:
        work()
    finally:
        for f in helpers:
            f.result()  # waits; re-raises a helper's exception
    return results


def run_range(kernel: Callable[..., object], total: int, *args, shares: int = 1, min_share: int = 1) -> list:
    """``kernel(t0, t1, *args)`` over ``[0, total)`` split into contiguous ranges, run by :func:`run_tasks`: ``shares``
    ranges per thread of :func:`kernel_threads` (more than one lets a thread that gets no core for a while leave its
    next range to the others), none shorter than ``min_share`` items; one range on the calling thread with one
    thread. Returns the kernel's results in range order. For kernels whose items are independent of each other, so
    that the result does not depend on the split."""
    threads = kernel_threads()
    n = min(shares * threads, max(1, total // max(1, min_share))) if threads > 1 else 1
    part = max(1, -(-total // n))
    return run_tasks(lambda c: kernel(c * part, min(total, (c + 1) * part), *args), -(-total // part) if total else 1)


def as_numpy(t: torch.Tensor, shape: Sequence[int], dtype: DTypeLike) -> np.ndarray:
    """A C-contiguous numpy array of a CPU tensor, reshaped and cast (no copy when nothing needs to change)."""
    return np.ascontiguousarray(t.detach().reshape(shape).numpy(), dtype=dtype)


def _dispatchers() -> dict:
    """``{"module.function": numba dispatcher}`` of every compiled function of :data:`KERNEL_MODULES`."""
    out = {}
    for module in KERNEL_MODULES:
        mod = importlib.import_module(f"torch_depth_sr.{module}")
        for name, obj in vars(mod).items():
            if hasattr(obj, "overloads") and getattr(getattr(obj, "py_func", None), "__module__", "") == mod.__name__:
                out[f"{module}.{name}"] = obj
    return out


def compiled_signatures() -> dict:
    """``{"module.function": [signature, ...]}``: what this process holds compiled or loaded from numba's cache."""
    return {name: [str(s) for s in d.signatures] for name, d in _dispatchers().items() if d.signatures}


def kernel_cache_dir() -> str:
    """Where numba caches these kernels: ``NUMBA_CACHE_DIR`` when set, else the ``__pycache__`` folder beside the
    kernel modules (``block_matching/__pycache__`` too), or numba's per-user folder when the package is read-only."""
    import numba

    if numba.config.CACHE_DIR:
        return str(numba.config.CACHE_DIR)
    beside = os.path.join(os.path.dirname(os.path.abspath(__file__)), "__pycache__")
    return beside if os.access(os.path.dirname(beside), os.W_OK) else "numba's per-user cache folder"
