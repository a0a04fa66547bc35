"""Planning a dataset run: what to restore, where it goes, what an earlier run finished. Reads only (except
``overwrite`` without ``resume``, which removes the earlier manifest: see :func:`plan_dataset`)."""
from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence as Seq, Union

from ..errors import UsageError
from ..datasets.files import check_writable, describe_files, file_identity
from .layouts import TUM_MAX_DIFFERENCE, Sequence, discover_recordings
from .manifest import MANIFEST_NAME, latest_records, manifest_files

__all__ = ["SequenceTask", "Plan", "plan_dataset"]


@dataclass(frozen=True)
class SequenceTask:
    """A sequence and, per frame, its output file, whether this run writes it, and the attempt number."""

    sequence: Sequence
    outputs: tuple[Path, ...]
    write: tuple[bool, ...]
    attempts: tuple[int, ...]
    out: Path  # the output folder (the manifest's records give outputs relative to it)

    @property
    def pending(self) -> int:
        return sum(self.write)


@dataclass(frozen=True)
class Plan:
    out: Path
    sequences: tuple[Sequence, ...]
    tasks: tuple[SequenceTask, ...]
    done: int  # frames an earlier run finished (ok in the manifest, output present)

    @property
    def frames(self) -> int:
        return sum(len(s.frames) for s in self.sequences)


def plan_dataset(recordings: Union[str, Path, Seq[Sequence]], out: Union[str, Path], *, resume: bool = False,
                 overwrite: bool = False, max_time_difference: float = TUM_MAX_DIFFERENCE) -> Plan:
    """Every check that needs no restoring, in this order: the recordings, the outputs (never an input, never an
    existing file unless ``overwrite``), the earlier manifest (continued with ``resume``, discarded with
    ``overwrite``, otherwise a :class:`UsageError`).

    With ``resume``, a frame is finished when the manifest's latest record for it is ``ok`` and its output exists;
    the other outputs of a folder that holds a manifest belong to that run and are written again. Without ``resume``,
    ``overwrite`` removes the earlier manifest files so that the run starts afresh.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"the output '{out}' is a file; give a folder for the restored recordings")
    if isinstance(recordings, (str, os.PathLike)):
        sequences = discover_recordings(recordings, max_time_difference=max_time_difference, exclude=[out])
    else:
        sequences = list(recordings)
        if not sequences or not all(isinstance(s, Sequence) for s in sequences):
            raise UsageError("recordings must be a folder or a non-empty list of Sequence (from discover_recordings); "
                             f"got {type(recordings).__name__}")
        if len({s.name for s in sequences}) != len(sequences):
            raise UsageError("two of the given sequences have the same name; their outputs would collide")
    outputs = [[out / s.output_name(f) for f in s.frames] for s in sequences]
    _check_outputs(sequences, outputs)
    files = manifest_files(out)
    if files and not resume and not overwrite:
        n = sum(r["status"] == "ok" for r in latest_records(files).values())
        raise UsageError(f"'{out}' holds the manifest of an earlier run ({n} frame{'s' if n != 1 else ''} done); "
                         "add --resume (resume=True) to finish it, or --overwrite (overwrite=True) to restore every "
                         "frame again")
    latest = latest_records(files) if resume else {}
    tasks, done, existing = [], 0, []
    for s, outs in zip(sequences, outputs):
        write, attempts = [], []
        for f, o in zip(s.frames, outs):
            r = latest.get((s.name, f.index))
            if r is not None and r.get("depth") != os.path.abspath(f.depth_path):
                raise UsageError(f"the manifest in '{out}' records frame {f.index} of '{s.name}' from "
                                 f"'{r.get('depth')}', but this run reads '{os.path.abspath(f.depth_path)}'; restore "
                                 "into another folder, or add --overwrite to restore every frame again")
            finished = r is not None and r["status"] == "ok" and o.is_file()
            done += finished
            write.append(not finished)
            attempts.append(int(r.get("attempt") or 1) + 1 if r is not None else 1)
            if not finished and o.exists() and not overwrite and not (resume and files):
                existing.append(o)
        tasks.append(SequenceTask(s, tuple(outs), tuple(write), tuple(attempts), out))
    if existing:
        raise UsageError(f"{describe_files(existing)} already exist{'s' if len(existing) == 1 else ''} and no manifest of "
                         f"'{out}' records {'it' if len(existing) == 1 else 'them'}; add --overwrite to replace, or "
                         "choose another output folder (nothing was written)")
    check_writable(out / MANIFEST_NAME)
    if overwrite and not resume:
        for p in files:
            with contextlib.suppress(FileNotFoundError):
                p.unlink()
    return Plan(out, tuple(sequences), tuple(tasks), done)


def _check_outputs(sequences: list[Sequence], outputs: list[list[Path]]) -> None:
    inputs = {}
    for s in sequences:
        for f in s.frames:
            for p in (f.depth_path, f.rgb_path):
                if p is not None:
                    inputs[file_identity(p)] = p
    seen: dict[str, Path] = {}
    for s, outs in zip(sequences, outputs):
        for f, o in zip(s.frames, outs):
            key = os.path.normcase(os.path.abspath(o))
            if key in seen:
                raise UsageError(f"frames '{seen[key]}' and '{f.depth_path}' would both be written to '{o}'; give "
                                 "the depth files of a recording distinct names")
            seen[key] = f.depth_path
            replaced = inputs.get(file_identity(o)) if o.exists() else None
            if replaced is not None:
                raise UsageError(f"the output '{o}' would replace the input '{replaced}'; choose an output folder "
                                 "outside the recordings (inputs are never replaced)")
            if o.is_dir():
                raise UsageError(f"the output '{o}' is a folder; choose another output folder")
