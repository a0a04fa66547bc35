"""Find benchmark scenes under a folder, whatever level of the layout it points at.

``find_scenes(root, track)`` accepts the whole data root (as ``shared/data``), a folder holding
only some dataset folders (e.g. ``middlebury2006/<Scene>/``), a dataset folder itself
(``.../middlebury2006``) or a single scene folder. Scene folders are recognised by their files
(see the layouts in :mod:`~torch_depth_sr.datasets.middlebury`,
:mod:`~torch_depth_sr.datasets.noisy_middlebury`, :mod:`~torch_depth_sr.datasets.real_sensor`),
searching up to three folder levels below ``root`` (symlinks are followed).

Tracks (``shared/docs/benchmark.md``):

* ``'paper'``, ``'sensor'``: Middlebury scenes with ground truth — 2005, 2006, 2003, 2001
  (21 scenes in the shared data). MiddEval3 ArtL only with ``include_eval3=True`` (it is Art again).
* ``'upsample-a'``: ``noisy_middlebury_ferstl2013``; ``'upsample-b'``: ``noisy_middlebury_park2011``.
* ``'real'``: TUM and SUN frames (NYU_raw only with ``include_unregistered=True``).
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, List, Optional, Union

from torch_depth_sr.datasets.middlebury import LAYOUTS, identify_scene_dir, load_middlebury_scene
from torch_depth_sr.datasets.noisy_middlebury import (
    VARIANTS,
    identify_noisy_scene,
    load_noisy_scene,
    noisy_scene_files,
)
from torch_depth_sr.datasets.real_sensor import DATASET as REAL_DATASET
from torch_depth_sr.datasets.real_sensor import FRAMES, identify_real_frame, load_real_frame
from torch_depth_sr.errors import DepthSRError

TRACKS = ("paper", "sensor", "upsample-a", "upsample-b", "real")
_YEAR_ORDER = {2005: 0, 2006: 1, 2003: 2, 2001: 3, 2014: 4}


@dataclass(frozen=True)
class SceneRecord:
    """A scene found on disk; ``load(**kwargs)`` reads it as a sample dict.

    Attributes:
        name: scene name (folder name, e.g. ``'Art'``, ``'art'``, ``'TUM'``).
        dataset: dataset folder name (e.g. ``'middlebury2005'``).
        year: Middlebury year (2014 = MiddEval3) or None.
        path: the scene folder.
        paths: the files used, by role (``'color'``, ``'gt'``, ``'depth'``, ``'depth_<f>'``...).
        loader: picklable callable returning the sample dict (upsampling loaders take ``factor``).
    """

    name: str
    dataset: str
    year: Optional[int]
    path: Path
    paths: Dict[str, Path] = field(compare=False)
    loader: Callable[..., dict] = field(compare=False, repr=False)

    def load(self, **kwargs) -> dict:
        return self.loader(**kwargs)


def _candidate_dirs(root: Path, max_depth: int = 3) -> List[Path]:
    out, seen = [], set()
    frontier = [root]
    for level in range(max_depth + 1):
        nxt = []
        for d in frontier:
            try:
                key = d.resolve()
            except OSError:
                continue
            if key in seen:
                continue
            seen.add(key)
            out.append(d)
            if level < max_depth:
                try:
                    nxt.extend(sorted(p for p in d.iterdir() if p.is_dir() and not p.name.startswith(".")))
                except OSError:
                    pass
        frontier = nxt
    return out


def _middlebury_record(d: Path, key) -> SceneRecord:
    lay = LAYOUTS[key]
    return SceneRecord(
        name=d.name,
        dataset=lay.folder,
        year=lay.year,
        path=d,
        paths={"color": d / lay.colour, "gt": d / lay.gt},
        loader=functools.partial(load_middlebury_scene, d, key),
    )


def find_scenes(
    root: Union[str, Path],
    track: str = "paper",
    include_eval3: bool = False,
    include_unregistered: bool = False,
) -> List[SceneRecord]:
    """Return the scenes of ``track`` found under ``root`` (sorted; see the module docstring).

    Examples:
        >>> recs = find_scenes(data_root(), 'paper')  # doctest: +SKIP
        >>> len(recs), recs[0].name, recs[0].load()['scale']  # doctest: +SKIP
        (21, 'Art', 3.0)
    """
    if track not in TRACKS:
        raise DepthSRError(f"track={track!r} is not allowed; use one of {TRACKS}")
    root = Path(root)
    if not root.is_dir():
        raise DepthSRError(f"data folder '{root}' does not exist; set TORCH_DEPTH_SR_DATA or pass the right path")
    recs: List[SceneRecord] = []
    for d in _candidate_dirs(root):
        if track in ("paper", "sensor"):
            key = identify_scene_dir(d)
            if key is None or (key == "eval3" and not include_eval3):
                continue
            recs.append(_middlebury_record(d, key))
        elif track in ("upsample-a", "upsample-b"):
            variant = "ferstl2013" if track == "upsample-a" else "park2011"
            if identify_noisy_scene(d) != variant:
                continue
            recs.append(
                SceneRecord(
                    name=d.name,
                    dataset=VARIANTS[variant],
                    year=2005,
                    path=d,
                    paths=noisy_scene_files(d, variant),
                    loader=functools.partial(load_noisy_scene, d, variant),
                )
            )
        else:  # real
            kind = identify_real_frame(d)
            if kind is None or (not FRAMES[kind][2] and not include_unregistered):
                continue
            c, dep, _ = FRAMES[kind]
            recs.append(
                SceneRecord(
                    name=kind,
                    dataset=REAL_DATASET,
                    year=None,
                    path=d,
                    paths={"color": d / c, "depth": d / dep},
                    loader=functools.partial(load_real_frame, d, kind),
                )
            )
    recs.sort(key=lambda r: (_YEAR_ORDER.get(r.year, 9), r.dataset, r.name.lower()))
    return recs


__all__ = ["SceneRecord", "TRACKS", "find_scenes"]
