"""Running sequences: each in order through one restorer (its state carried frame to frame), several at once in a
process pool (``workers``), progress per sequence and overall; the manifest is written by this process only."""
from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import queue as queue_mod
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from typing import Callable, Optional

import torch
from tqdm import tqdm

from ..datasets.io import read_depth_stored, read_rgb, write_depth
from ..errors import DepthSRError, describe_error
from ..datasets.files import as_numpy, stored_layout, to_model_input, with_path
from .manifest import ManifestWriter
from .plan import SequenceTask
from .restorers import Restorer

__all__ = ["RunStats", "run_task", "execute"]


@dataclass
class RunStats:
    """What one process restored."""

    written: int = 0
    failed: int = 0
    failures: list = field(default_factory=list)  # the failed records


def _check_restorer(r) -> None:
    if not (callable(getattr(r, "step", None)) and callable(getattr(r, "reset", None))):
        raise DepthSRError(f"the restorer factory returned {type(r).__name__}, which has no .step(depth, rgb) and "
                           ".reset(); pass a callable that builds one (e.g. PretrainedRestorer('denoise'))")


def run_task(task: SequenceTask, restorer: Restorer, emit: Callable[[tuple], None]) -> None:
    """Step ``restorer`` through ``task``'s sequence in order, writing the frames marked ``write``.

    A stateful restorer (the default; ``stateful = False`` opts out) is reset and replays the sequence from its
    first frame, so that the state at each written frame is the one an uninterrupted run had: finished frames are
    read and stepped but neither written nor recorded. ``emit`` gets ``("frame", name, record)`` for each written
    frame and ``("step", name, None)`` for each replayed one.
    """
    s = task.sequence
    if not task.pending:
        return
    restorer.reset()
    stateful = getattr(restorer, "stateful", True)
    for i, frame in enumerate(s.frames):
        write = task.write[i]
        if not write and not stateful:
            continue
        t0 = time.perf_counter()
        error = None
        try:
            depth = read_depth_stored(frame.depth_path)
            rgb = None if frame.rgb_path is None else torch.from_numpy(read_rgb(frame.rgb_path)).permute(2, 0, 1)
            restored = restorer.step(to_model_input(depth), rgb)
            if write:
                restored = as_numpy(restored).astype(depth.dtype, copy=False)
                task.outputs[i].parent.mkdir(parents=True, exist_ok=True)
                write_depth(task.outputs[i], stored_layout(restored, frame.depth_path))
        except Exception as e:  # noqa: BLE001 - one bad frame is recorded; the sequence goes on
            error = with_path(e, frame.depth_path, describe_error(e))
        if not write:
            emit(("step", s.name, None))
            continue
        emit(("frame", s.name, {
            "sequence": s.name, "index": frame.index, "timestamp": frame.timestamp,
            "depth": os.path.abspath(frame.depth_path),
            "rgb": None if frame.rgb_path is None else os.path.abspath(frame.rgb_path),
            "output": task.outputs[i].relative_to(task.out).as_posix(),
            "status": "ok" if error is None else "failed", "seconds": round(time.perf_counter() - t0, 4),
            "attempt": task.attempts[i], "error": error,
        }))


class _Progress:
    """An overall bar (frames written) and one bar per running sequence (frames stepped); terminals only."""

    def __init__(self, tasks: list[SequenceTask], desc: str, enabled: bool):
        self.disable = None if enabled else True  # None: tqdm shows bars on terminals, nothing in logs
        self.steps = {t.sequence.name: _steps(t) for t in tasks}
        self.overall = tqdm(total=sum(t.pending for t in tasks), desc=desc, unit="frame", disable=self.disable)
        self.bars: dict = {}
        self.failed = 0

    def update(self, name: str, failed: bool = False) -> None:
        bar = self.bars.get(name)
        if bar is None:
            bar = self.bars[name] = tqdm(total=self.steps.get(name), desc=name, unit="frame", leave=False,
                                         disable=self.disable)
        bar.update()
        if bar.n >= (bar.total or 0):
            bar.close()
        self.failed += failed
        if self.failed and failed:
            self.overall.set_postfix(failed=self.failed)

    def frame(self, name: str, failed: bool) -> None:
        self.overall.update()
        self.update(name, failed)

    def end(self, name: str) -> None:
        bar = self.bars.pop(name, None)
        if bar is not None:
            bar.close()

    def close(self) -> None:
        for bar in self.bars.values():
            bar.close()
        self.overall.close()


def _steps(t: SequenceTask) -> int:
    # a stateful restorer replays from the first frame; the bar counts what will be stepped (an upper bound)
    return len(t.sequence.frames) if t.pending else 0


def execute(tasks: list[SequenceTask], factory: Callable[[], object], writer: ManifestWriter, *, workers: int = 0,
            threads: Optional[int] = None, desc: str = "restore", progress: bool = True) -> RunStats:
    """Restore ``tasks`` (in this process, or ``workers > 1`` processes), appending each frame's record to
    ``writer``. Raises the first error that is not one frame's (a restorer that cannot be built, a dead worker)."""
    stats = RunStats()
    tasks = [t for t in tasks if t.pending]
    bars = _Progress(tasks, desc, progress)

    def handle(msg: tuple) -> None:
        kind, name, record = msg
        if kind == "end":
            bars.end(name)
            return
        if kind == "step":
            bars.update(name)
            return
        writer.append(record)
        failed = record["status"] != "ok"
        stats.written += not failed
        stats.failed += failed
        if failed:
            stats.failures.append(record)
        bars.frame(name, failed)

    try:
        if workers <= 1 or len(tasks) <= 1:
            _run_here(tasks, factory, threads, handle)
        else:
            _run_pool(tasks, factory, workers, threads, handle)
    finally:
        bars.close()
    return stats


def _run_here(tasks, factory, threads, handle) -> None:
    if not tasks:
        return
    old = torch.get_num_threads()
    if threads is not None:
        torch.set_num_threads(threads)
    try:
        restorer = factory()
        _check_restorer(restorer)
        for t in tasks:
            run_task(t, restorer, handle)
            handle(("end", t.sequence.name, None))
    finally:
        torch.set_num_threads(old)


# ---- the process pool ---------------------------------------------------------------------------------------------

_WORKER: dict = {}


def _init_worker(factory, threads: int, q) -> None:
    torch.set_num_threads(threads)
    _WORKER.update(factory=factory, queue=q, restorer=None)


def _pool_task(task: SequenceTask) -> None:
    q = _WORKER["queue"]
    error = None
    try:
        if _WORKER["restorer"] is None:
            r = _WORKER["factory"]()
            _check_restorer(r)
            _WORKER["restorer"] = r
        run_task(task, _WORKER["restorer"], q.put)
    except BaseException as e:  # noqa: BLE001 - sent to the parent, which stops the run with it
        error = e if _picklable(e) else DepthSRError(describe_error(e))
    finally:
        q.put(("end", task.sequence.name, error))


def _picklable(e: BaseException) -> bool:
    import pickle

    try:
        pickle.loads(pickle.dumps(e))
    except Exception:  # noqa: BLE001
        return False
    return True


def _run_pool(tasks, factory, workers, threads, handle) -> None:
    ctx = mp.get_context("spawn")  # fork after torch's thread pools start can hang
    q = ctx.Queue()
    per_worker = threads if threads is not None else max(1, torch.get_num_threads() // workers)
    # longest sequences first: the pool finishes sooner (the outputs do not depend on the order)
    order = sorted(tasks, key=lambda t: (-len(t.sequence.frames), t.sequence.name))
    error: Optional[BaseException] = None
    with ProcessPoolExecutor(max_workers=min(workers, len(tasks)), mp_context=ctx, initializer=_init_worker,
                             initargs=(factory, per_worker, q)) as pool:
        futures = {t.sequence.name: pool.submit(_pool_task, t) for t in order}
        running = set(futures)
        while running:
            try:
                msg = q.get(timeout=0.2)
            except queue_mod.Empty:
                for name in list(running):
                    f = futures[name]
                    if f.done() and (f.cancelled() or f.exception() is not None):
                        running.discard(name)
                        if error is None and not f.cancelled():
                            error = DepthSRError(
                                f"a worker process died while restoring the sequence '{name}' "
                                f"({describe_error(f.exception())}); the frames written so far are in the manifest: "
                                "rerun with --resume")
                continue
            if msg[0] == "end":
                running.discard(msg[1])
                handle(("end", msg[1], None))
                if msg[2] is not None and error is None:
                    error = msg[2]
                    for name in list(running):  # stop: what has not started will not
                        if futures[name].cancel():
                            running.discard(name)
            else:
                handle(msg)
    with contextlib.suppress(Exception):
        q.close()
    if error is not None:
        raise error
