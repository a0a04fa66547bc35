""":func:`restore_dataset`: every frame of every recording under a folder, restored once, with a manifest."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional, Sequence as Seq, Union

from ..errors import DepthSRError, UsageError
from .distributed import assign_sequences, setup
from .layouts import TUM_MAX_DIFFERENCE, Sequence
from .manifest import ManifestWriter, merge_manifest, shard_path
from .plan import plan_dataset
from .restorers import PretrainedRestorer
from .runner import RunStats, execute

__all__ = ["RestoreSummary", "restore_dataset"]


@dataclass(frozen=True)
class RestoreSummary:
    """The outcome of :func:`restore_dataset` (the same on every rank)."""

    out: Path
    manifest: Path
    sequences: int
    frames: int  # frames of the recordings
    written: int  # restored and written by this run
    skipped: int  # finished by an earlier run (resume)
    failed: int  # recorded as failed by this run
    missing: int  # frames without an ok record after this run (failed, or not reached)
    unmatched: int  # TUM depth.txt frames with no colour frame in time (not part of the sequences)
    seconds: float
    processes: int  # torchrun ranks
    failures: list = field(default_factory=list)  # this run's failed records

    @property
    def ok(self) -> bool:
        return self.missing == 0


def restore_dataset(recordings: Union[str, Path, Seq[Sequence]], out: Union[str, Path], *,
                    restorer: Optional[Callable[[], object]] = None, workers: int = 0, resume: bool = False,
                    overwrite: bool = False, threads: Optional[int] = None,
                    max_time_difference: float = TUM_MAX_DIFFERENCE, progress: bool = True) -> RestoreSummary:
    """Restore every frame of the recordings under ``recordings`` into ``out``, each sequence in order.

    Each restored map is written to ``out/<sequence>/<its path in the recording>`` with its input's format, dtype
    and units (16-bit PNG millimetres in, 16-bit PNG millimetres out), atomically; ``out/manifest.jsonl`` records
    every frame (see :mod:`torch_depth_sr.recordings.manifest`). Under ``torchrun`` the sequences are shared among
    the ranks (each sequence whole on one rank: its state stays in one process), so each frame is written once.

    Args:
        recordings: a folder (see :func:`discover_recordings` for the layouts) or a list of sequences.
        out: the output folder; it must not hold the inputs.
        restorer: a picklable factory of per-sequence restorers (``.step(depth, rgb)``, ``.reset()``; see
            :mod:`torch_depth_sr.recordings.restorers`); default ``PretrainedRestorer()`` (frame by frame, what
            ``restore_depth`` runs without a model: the ``default`` tier to denoise).
        workers: ``> 1``: that many processes restore different sequences at once (per ``torchrun`` rank).
        resume: continue the run whose manifest ``out`` holds: finished frames are kept (not written again), the
            others restored. A sequence whose restorer carries state is replayed from its first frame so that every
            output is the one an uninterrupted run writes (bit for bit with the same ``threads``).
        overwrite: replace existing outputs; without ``resume`` the earlier manifest is discarded and every frame
            restored again.
        threads: torch threads per process (default: as set, e.g. ``OMP_NUM_THREADS``; ``workers`` processes share
            this process's threads). Results can differ in the last bit between thread counts (parallel sums
            round differently): give the same ``threads`` to runs whose outputs must be identical.
        max_time_difference: TUM ``depth.txt`` + ``rgb.txt`` pairing tolerance in seconds.
        progress: tqdm bars (on terminals): overall and per running sequence.

    Returns:
        A :class:`RestoreSummary`; ``summary.ok`` when every frame has been restored.

    Raises:
        UsageError: before anything is written: no recordings, an output that is an input or exists (without
            ``overwrite``), a manifest of an earlier run without ``resume``/``overwrite``.
    """
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 0:
        raise UsageError(f"workers must be a whole number >= 0; got {workers!r}")
    if threads is not None and (not isinstance(threads, int) or isinstance(threads, bool) or threads < 1):
        raise UsageError(f"threads must be a whole number >= 1 or None; got {threads!r}")
    factory = PretrainedRestorer() if restorer is None else restorer
    if not callable(factory):
        raise UsageError(f"restorer must be a callable that builds a restorer (a factory); got "
                         f"{type(factory).__name__}")
    t0 = time.perf_counter()
    group = setup()
    try:
        plan = None
        if group.rank == 0:
            try:
                plan = plan_dataset(recordings, out, resume=resume, overwrite=overwrite,
                                    max_time_difference=max_time_difference)
            except DepthSRError as e:
                plan = e
        plan = group.broadcast(plan)  # one reading of the folders: every rank works from the same plan
        if isinstance(plan, BaseException):
            raise plan
        owners = assign_sequences([len(s.frames) for s in plan.sequences], group.world)
        mine = [t for t, r in zip(plan.tasks, owners) if r == group.rank]
        desc = f"restore [rank {group.rank}]" if group.distributed else "restore"
        stats = RunStats()
        if any(t.pending for t in mine):
            with ManifestWriter(shard_path(plan.out, group.rank)) as writer:
                stats = execute(mine, factory, writer, workers=workers, threads=threads, desc=desc,
                                progress=progress)
        group.barrier()  # every rank's records are on disk
        every = group.gather(stats)
        summary = None
        if group.rank == 0:
            path, records = merge_manifest(plan.out, order=[s.name for s in plan.sequences])
            planned = {(s.name, f.index) for s in plan.sequences for f in s.frames}
            ok = sum(1 for r in records if r["status"] == "ok" and (r["sequence"], r["index"]) in planned)
            summary = RestoreSummary(
                out=plan.out, manifest=path, sequences=len(plan.sequences), frames=plan.frames,
                written=sum(s.written for s in every), skipped=plan.done, failed=sum(s.failed for s in every),
                missing=plan.frames - ok, unmatched=sum(s.unmatched for s in plan.sequences),
                seconds=round(time.perf_counter() - t0, 3), processes=group.world,
                failures=[r for s in every for r in s.failures])
        return group.broadcast(summary)
    finally:
        group.close()
