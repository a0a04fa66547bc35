"""Finding the recordings under a folder: :func:`discover_recordings` → :class:`Sequence` of :class:`Frame`.

A *recording* (a sequence) is a folder in one of these layouts, tried in this order:

* ``tum-associations``: TUM RGB-D with ``associations.txt`` (``t1 file1 t2 file2`` per line, as TUM's
  ``associate.py`` writes it; the column whose path names a ``depth`` folder or file is the depth).
* ``tum-lists``: TUM RGB-D with ``depth.txt`` + ``rgb.txt`` (``timestamp file`` per line): each depth frame is
  paired with the colour frame nearest in time within ``max_time_difference`` seconds, greedily by smallest
  difference, each colour frame used once (what ``associate.py`` does); a depth frame without a colour frame in
  that window is left out and counted in :attr:`Sequence.unmatched`.
* ``index``: ``index.txt`` with one line per frame, ``id depth/<file> rgb/<file> [extra]`` (the real sequences of
  the shared data, ``real_sequences/<name>/``).
* ``folder``: a ``depth/`` folder with a colour folder next to it (``rgb/``, ``color/``, ``colour/``, ``image/`` or
  ``images/``; none = depth only), paired by name or by sorted order with equal counts, as ``torch-depth-sr
  restore DEPTH_DIR RGB_DIR`` pairs them.

A folder in none of these layouts is searched for recordings inside it, so a root holding several recordings gives
several sequences (named by their path under the root, in sorted order). Paths in the listing files are relative to
the recording's folder. Every file is checked to exist before anything is restored.
"""
from __future__ import annotations

import bisect
import os
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Iterable, Optional, Union

from ..errors import UsageError
from ..datasets.files import DEPTH_EXTS, RGB_EXTS, pair_folders

__all__ = ["Frame", "Sequence", "LAYOUTS", "discover_recordings", "associate_timestamps", "recording_layout"]

PathLike = Union[str, Path]
LAYOUTS = ("tum-associations", "tum-lists", "index", "folder")
COLOUR_FOLDERS = ("rgb", "color", "colour", "image", "images")
TUM_MAX_DIFFERENCE = 0.02  # seconds: associate.py's default


@dataclass(frozen=True)
class Frame:
    """One depth map of a sequence and its colour image (``None``: depth only)."""

    index: int  # position in the sequence, 0-based
    timestamp: Optional[float]  # seconds (the depth frame's, TUM layouts), else None
    depth_path: Path
    rgb_path: Optional[Path]


@dataclass(frozen=True)
class Sequence:
    """A recording: frames restored in this order, with the restorer's state carried from one to the next."""

    name: str  # the folder's path under the discovered root ('/'-separated); the root's own name if it is one
    frames: tuple[Frame, ...]
    folder: Path
    layout: str  # one of LAYOUTS
    unmatched: int = field(default=0)  # tum-lists: depth frames with no colour frame in time (left out)

    def output_name(self, frame: Frame) -> PurePosixPath:
        """Where ``frame``'s restored map goes under the output folder: ``<name>/<depth path in the folder>``."""
        try:
            rel = PurePosixPath(Path(os.path.abspath(frame.depth_path)).relative_to(os.path.abspath(self.folder)))
        except ValueError:  # a listing that points outside the recording's folder
            rel = PurePosixPath("depth", frame.depth_path.name)
        return PurePosixPath(self.name) / rel


def discover_recordings(root: PathLike, *, max_time_difference: float = TUM_MAX_DIFFERENCE,
                        exclude: Iterable[PathLike] = ()) -> list[Sequence]:
    """The recordings under ``root`` (or ``root`` itself), in a deterministic order (sorted by name).

    Args:
        root: a recording folder, or a folder holding recordings at any depth.
        max_time_difference: TUM ``depth.txt`` + ``rgb.txt``: the largest time between a depth frame and its
            colour frame, in seconds (``associate.py``'s ``--max_difference``; default 0.02).
        exclude: folders not to search (e.g. the output folder when it lies under ``root``).

    Raises:
        UsageError: ``root`` is missing or not a folder, holds no recording, or a recording's listing is malformed
            or names a file that does not exist (the message names the file and line).
    """
    root = Path(root)
    if not root.exists():
        raise UsageError(f"recordings root '{root}' does not exist; check the path")
    if not root.is_dir():
        raise UsageError(f"recordings root '{root}' is a file; give a recording folder or a folder of recordings "
                         f"({_LAYOUT_HELP})")
    if not (isinstance(max_time_difference, (int, float)) and max_time_difference > 0):
        raise UsageError(f"max_time_difference must be a number of seconds > 0; got {max_time_difference!r}")
    skip = {_ident(Path(p)) for p in exclude} - {None}
    found: list[Sequence] = []
    _walk(root, root, skip, set(), found, float(max_time_difference))
    if not found:
        raise UsageError(f"no recordings under '{root}'; a recording is a folder with {_LAYOUT_HELP}")
    names = [s.name for s in found]
    return [found[i] for i in sorted(range(len(found)), key=lambda i: names[i])]


_LAYOUT_HELP = ("associations.txt (TUM), depth.txt + rgb.txt (TUM), index.txt ('id depth/<file> rgb/<file>' per "
                "line) or a depth/ folder with rgb/ (or color/) next to it")


def recording_layout(folder: PathLike) -> Optional[str]:
    """The layout of ``folder`` (one of :data:`LAYOUTS`), or None when it is not a recording itself."""
    d = Path(folder)
    if (d / "associations.txt").is_file():
        return "tum-associations"
    if (d / "depth.txt").is_file() and (d / "rgb.txt").is_file():
        return "tum-lists"
    if (d / "index.txt").is_file():
        return "index"
    if (d / "depth").is_dir():
        return "folder"
    return None


def _ident(p: Path):
    try:
        st = p.stat()
    except OSError:
        return None
    return st.st_dev, st.st_ino


def _walk(d: Path, root: Path, skip: set, seen: set, found: list, tol: float) -> None:
    ident = _ident(d)
    if ident in seen or ident in skip:  # a symlink loop, or the output folder
        return
    seen.add(ident)
    layout = recording_layout(d)
    if layout is not None:
        name = d.relative_to(root).as_posix() if d != root else (Path(os.path.abspath(root)).name or "recording")
        found.append(_READERS[layout](d, name, tol))
        return
    for sub in sorted(p for p in d.iterdir() if p.is_dir() and not p.name.startswith(".")):
        _walk(sub, root, skip, seen, found, tol)


# ---- the layouts ------------------------------------------------------------------------------------------------

def _lines(path: Path):
    """``(line number, tokens)`` of a listing: ``#`` comments and blank lines skipped; commas and tabs separate."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise UsageError(f"cannot read '{path}': {e}") from e
    for n, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if line and not line.startswith("#"):
            yield n, line.replace(",", " ").replace("\t", " ").split()


def _time(token: str, path: Path, n: int) -> float:
    try:
        return float(token)
    except ValueError:
        raise UsageError(f"'{path}' line {n}: expected a timestamp in seconds, got {token!r}") from None


def _file(folder: Path, rel: str, listing: Path, n: int, what: str) -> Path:
    p = folder / rel
    if not p.is_file():
        raise UsageError(f"'{listing}' line {n} names the {what} file '{rel}', but '{p}' does not exist")
    if what == "depth" and p.suffix.lower() not in DEPTH_EXTS:
        raise UsageError(f"'{listing}' line {n}: the depth file '{rel}' has the suffix '{p.suffix}'; allowed are "
                         f"{', '.join(DEPTH_EXTS)} (lossy formats such as JPEG cannot hold depth)")
    if what == "colour" and p.suffix.lower() not in RGB_EXTS:
        raise UsageError(f"'{listing}' line {n}: the colour file '{rel}' has the suffix '{p.suffix}'; allowed are "
                         f"{', '.join(RGB_EXTS)}")
    return p


def _sequence(folder: Path, name: str, layout: str, rows: list, unmatched: int = 0) -> Sequence:
    """``rows``: ``(timestamp, depth path, rgb path, where)`` in order (``where``: the listing's line, for
    messages); refuses an empty list and a repeated depth file."""
    if not rows:
        raise UsageError(f"the recording '{folder}' ({layout}) lists no frames")
    seen: dict = {}
    for _, d, _, where in rows:
        if d in seen:
            raise UsageError(f"{where} lists the depth file '{d}' again (first at {seen[d]}); each depth frame can "
                             "be restored once")
        seen[d] = where
    frames = tuple(Frame(i, t, d, c) for i, (t, d, c, _) in enumerate(rows))
    return Sequence(name, frames, folder, layout, unmatched)


def _depth_column(a: str, b: str) -> Optional[int]:
    """0 when path ``a`` is the depth of an associations line, 1 when ``b`` is, None when the names do not tell."""
    def is_depth(s: str) -> bool:
        return any("depth" in part.lower() for part in PurePosixPath(s.replace("\\", "/")).parts)

    da, db = is_depth(a), is_depth(b)
    if da != db:
        return 0 if da else 1
    sa, sb = Path(a).suffix.lower() in DEPTH_EXTS, Path(b).suffix.lower() in DEPTH_EXTS
    if sa != sb:  # e.g. depth .png with colour .jpg
        return 0 if sa else 1
    return None


def _read_associations(folder: Path, name: str, tol: float) -> Sequence:
    listing = folder / "associations.txt"
    rows, column = [], None
    for n, tok in _lines(listing):
        if len(tok) < 4:
            raise UsageError(f"'{listing}' line {n}: expected 'time file time file' (TUM associate.py output), got "
                             f"{len(tok)} field{'s' if len(tok) != 1 else ''}: {' '.join(tok)!r}")
        if column is None:
            column = _depth_column(tok[1], tok[3])
            if column is None:
                raise UsageError(f"'{listing}' line {n}: cannot tell which of '{tok[1]}' and '{tok[3]}' is the depth "
                                 "file; name the depth folder or files 'depth' (TUM: depth/<time>.png)")
        td, fd, fc = (tok[0], tok[1], tok[3]) if column == 0 else (tok[2], tok[3], tok[1])
        rows.append((_time(td, listing, n), _file(folder, fd, listing, n, "depth"),
                     _file(folder, fc, listing, n, "colour"), f"'{listing}' line {n}"))
    return _sequence(folder, name, "tum-associations", rows)


def _read_list(path: Path) -> list[tuple[float, str, int]]:
    out = []
    for n, tok in _lines(path):
        if len(tok) < 2:
            raise UsageError(f"'{path}' line {n}: expected 'timestamp filename' (TUM format), got {' '.join(tok)!r}")
        out.append((_time(tok[0], path, n), tok[1], n))
    return out


def associate_timestamps(first: list[float], second: list[float], max_difference: float) -> list[tuple[int, int]]:
    """Pairs ``(i, j)`` of ``first[i]`` and ``second[j]`` closer than ``max_difference``, as TUM's ``associate.py``:
    candidate pairs by increasing time difference, each element used at most once; sorted by ``i``.

    Examples:
        >>> associate_timestamps([0.0, 1.0, 2.0], [0.01, 1.5, 2.005], 0.02)
        [(0, 0), (2, 2)]
    """
    order = sorted(range(len(second)), key=lambda j: second[j])
    times = [second[j] for j in order]
    candidates = []
    for i, a in enumerate(first):
        lo = bisect.bisect_left(times, a - max_difference)
        for k in range(lo, len(times)):
            if times[k] - a >= max_difference:
                break
            if abs(a - times[k]) < max_difference:
                candidates.append((abs(a - times[k]), a, times[k], i, order[k]))
    candidates.sort()
    used_i, used_j, pairs = set(), set(), []
    for _, _, _, i, j in candidates:
        if i not in used_i and j not in used_j:
            used_i.add(i)
            used_j.add(j)
            pairs.append((i, j))
    return sorted(pairs)


def _read_lists(folder: Path, name: str, tol: float) -> Sequence:
    depth_list, rgb_list = folder / "depth.txt", folder / "rgb.txt"
    depths = sorted(_read_list(depth_list))
    rgbs = _read_list(rgb_list)
    pairs = associate_timestamps([t for t, _, _ in depths], [t for t, _, _ in rgbs], tol)
    rows = []
    for i, j in pairs:
        t, fd, nd = depths[i]
        _, fc, nc = rgbs[j]
        rows.append((t, _file(folder, fd, depth_list, nd, "depth"), _file(folder, fc, rgb_list, nc, "colour"),
                     f"'{depth_list}' line {nd}"))
    if not rows and depths and rgbs:
        raise UsageError(f"no depth frame of '{depth_list}' has a colour frame of '{rgb_list}' within "
                         f"{tol} s; raise the tolerance (--max-time-difference) or check the timestamps")
    return _sequence(folder, name, "tum-lists", rows, unmatched=len(depths) - len(rows))


def _read_index(folder: Path, name: str, tol: float) -> Sequence:
    listing = folder / "index.txt"
    rows = []
    for n, tok in _lines(listing):
        if len(tok) < 3:
            raise UsageError(f"'{listing}' line {n}: expected 'id depth/<file> rgb/<file> [extra]', got "
                             f"{' '.join(tok)!r}")
        rows.append((None, _file(folder, tok[1], listing, n, "depth"), _file(folder, tok[2], listing, n, "colour"),
                     f"'{listing}' line {n}"))
    return _sequence(folder, name, "index", rows)


def _read_folder(folder: Path, name: str, tol: float) -> Sequence:
    colour = [folder / c for c in COLOUR_FOLDERS if (folder / c).is_dir()]
    if len(colour) > 1:
        raise UsageError(f"the recording '{folder}' has {len(colour)} colour folders "
                         f"({', '.join(c.name + '/' for c in colour)}); keep one next to depth/")
    rgb_dir = colour[0] if colour else None
    try:
        depths, rgbs = pair_folders(folder / "depth", rgb_dir)
    except UsageError as e:
        raise UsageError(f"the recording '{folder}': {e}") from e
    return _sequence(folder, name, "folder", [(None, d, c, f"'{d}'") for d, c in zip(depths, rgbs)])


_READERS = {"tum-associations": _read_associations, "tum-lists": _read_lists, "index": _read_index,
            "folder": _read_folder}
