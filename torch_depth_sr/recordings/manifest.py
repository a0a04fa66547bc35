"""The manifest: a JSON-lines record of every frame a run restored, next to the outputs.

One line per frame attempt::

    {"sequence": "desk", "index": 3, "timestamp": null, "depth": "/data/desk/depth/000003.png",
     "rgb": "/data/desk/rgb/000003.jpg", "output": "desk/depth/000003.png", "status": "ok", "seconds": 0.41,
     "attempt": 1, "error": null}

``depth``/``rgb`` are absolute input paths, ``output`` is relative to the output folder, ``status`` is ``"ok"`` or
``"failed"`` (then ``error`` holds the one-line reason), ``attempt`` counts the runs that tried this frame.

While a run works, each process appends to its own shard ``manifest.rank<R>.jsonl`` (``write`` + ``flush`` +
``fsync`` per line, so a record on disk is complete and survives a crash of the machine). A process killed in the
middle of a line leaves a partial last line: readers skip lines that are not a whole record, and the next writer
starts on a fresh line. At the end :func:`merge_manifest` folds the shards and an earlier ``manifest.jsonl`` into
one ``manifest.jsonl`` (one record per frame, the highest attempt, sorted by sequence and index), written
atomically, and removes the shards.
"""
from __future__ import annotations

import contextlib
import json
import os
import re
from pathlib import Path
from typing import Iterable, Optional

from ..datasets.io import atomic_write_bytes

__all__ = ["MANIFEST_NAME", "ManifestWriter", "shard_path", "manifest_files", "read_manifest", "latest_records",
           "merge_manifest", "RECORD_KEYS"]

MANIFEST_NAME = "manifest.jsonl"
RECORD_KEYS = ("sequence", "index", "timestamp", "depth", "rgb", "output", "status", "seconds", "attempt", "error")
_SHARD = re.compile(r"^manifest\.rank(\d+)\.jsonl$")


def shard_path(out: Path, rank: int) -> Path:
    return Path(out) / f"manifest.rank{rank}.jsonl"


def manifest_files(out: Path) -> list[Path]:
    """``manifest.jsonl`` (if any), then the shards by rank: the order in which their records were written."""
    out = Path(out)
    if not out.is_dir():
        return []
    shards = sorted((int(m.group(1)), p) for p in out.iterdir() if (m := _SHARD.match(p.name)) and p.is_file())
    main = [out / MANIFEST_NAME] if (out / MANIFEST_NAME).is_file() else []
    return main + [p for _, p in shards]


class ManifestWriter:
    """Appends records to one file, each line written whole and synced before :meth:`append` returns."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f = open(self.path, "ab")
        if self._f.tell() > 0 and not _ends_with_newline(self.path):
            self._write(b"\n")  # a killed writer's partial line stays alone on its line (readers skip it)

    def append(self, record: dict) -> None:
        self._write((json.dumps(record, ensure_ascii=False) + "\n").encode("utf-8"))

    def _write(self, data: bytes) -> None:
        self._f.write(data)
        self._f.flush()
        os.fsync(self._f.fileno())

    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> "ManifestWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _ends_with_newline(path: Path) -> bool:
    with open(path, "rb") as f:
        f.seek(-1, os.SEEK_END)
        return f.read(1) == b"\n"


def read_manifest(path: Path) -> list[dict]:
    """The whole records of one manifest file, in file order; partial or foreign lines are skipped."""
    records = []
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        return records
    for line in data.split(b"\n"):
        if not line.strip():
            continue
        try:
            r = json.loads(line.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError):
            continue  # the partial last line of a killed process
        if isinstance(r, dict) and isinstance(r.get("sequence"), str) and isinstance(r.get("index"), int) \
                and r.get("status") in ("ok", "failed"):
            records.append(r)
    return records


def latest_records(paths: Iterable[Path]) -> dict[tuple[str, int], dict]:
    """One record per ``(sequence, index)``: the highest ``attempt``, the last written among equals."""
    latest: dict[tuple[str, int], dict] = {}
    for p in paths:
        for r in read_manifest(p):
            key = (r["sequence"], r["index"])
            old = latest.get(key)
            if old is None or int(r.get("attempt") or 1) >= int(old.get("attempt") or 1):
                latest[key] = r
    return latest


def merge_manifest(out: Path, order: Optional[list[str]] = None) -> tuple[Path, list[dict]]:
    """Fold ``manifest.jsonl`` and the shards of ``out`` into ``manifest.jsonl`` (atomically), remove the shards.

    Records are sorted by sequence (in ``order``, then by name for sequences not in it) and index.
    Returns the manifest's path and its records.
    """
    out = Path(out)
    files = manifest_files(out)
    latest = latest_records(files)
    rank = {name: i for i, name in enumerate(order or [])}
    records = sorted(latest.values(), key=lambda r: (rank.get(r["sequence"], len(rank)), r["sequence"], r["index"]))
    path = out / MANIFEST_NAME
    atomic_write_bytes(path, b"".join((json.dumps(r, ensure_ascii=False) + "\n").encode("utf-8") for r in records))
    for p in files:
        if p != path:
            with contextlib.suppress(FileNotFoundError):
                p.unlink()
    return path, records
