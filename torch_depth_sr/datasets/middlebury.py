"""Middlebury stereo scenes (2001, 2003, 2005, 2006, MiddEval3) as guided-depth samples.

Layouts and disparity scales, as checked in ``shared/data/README.md``:

=====================  ======================  ===========================  =====================
dataset folder         colour / ground truth   scale (grey levels per px)   unknown
=====================  ======================  ===========================  =====================
middlebury2001         imL.png / groundtruth   info.txt (Tsukuba 16, Venus 8)  0
middlebury2003         im2.png / disp2.png     4 (quarter size)             0
middlebury2005, 2006   view1.png / disp1.png   3 (third size)               0
middlebury_eval3_half  im0.png / disp0GT.pfm   1 (float px, rows flipped)   +inf (-> 0 here)
=====================  ======================  ===========================  =====================

Each sample is a dict: ``depth`` (1,H,W) float32 (here a copy of the clean ground truth; the
protocols in :mod:`torch_depth_sr.degradations` replace it with a degraded input),
``rgb`` (3,H,W) in [0,1], ``gt`` (1,H,W) (0 = unknown), ``mask`` (1,H,W) (1 = gt known),
``scale`` (float), ``name`` (scene folder name, e.g. ``'Art'``), ``dataset``
(e.g. ``'middlebury2005'``), ``year`` (int; 2014 for MiddEval3) and ``path`` (str).
"""

from __future__ import annotations

import shutil
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Optional, Sequence, Tuple, Union

import numpy as np
from torch.utils.data import Dataset

from torch_depth_sr.datasets.io import DataFileError, read_pfm, read_png_depth, read_rgb, sample_from_arrays
from torch_depth_sr.errors import DepthSRError


@dataclass(frozen=True)
class MiddleburyLayout:
    year: int
    folder: str  # dataset folder name under the data root
    colour: str
    gt: str


LAYOUTS: Dict[Union[int, str], MiddleburyLayout] = {
    2001: MiddleburyLayout(2001, "middlebury2001", "imL.png", "groundtruth.png"),
    2003: MiddleburyLayout(2003, "middlebury2003", "im2.png", "disp2.png"),
    2005: MiddleburyLayout(2005, "middlebury2005", "view1.png", "disp1.png"),
    2006: MiddleburyLayout(2006, "middlebury2006", "view1.png", "disp1.png"),
    "eval3": MiddleburyLayout(2014, "middlebury_eval3_half", "im0.png", "disp0GT.pfm"),
}

#: Scenes with ground truth in the shared data (the ``paper``/``sensor`` tracks).
SCENES: Dict[int, Tuple[str, ...]] = {
    2005: ("Art", "Books", "Dolls", "Laundry", "Moebius", "Reindeer"),
    2006: ("Baby1", "Baby2", "Baby3", "Cloth1", "Cloth2", "Cloth3", "Cloth4", "Midd1", "Midd2", "Wood1", "Wood2"),
    2003: ("Cones", "Teddy"),
    2001: ("Tsukuba", "Venus"),
}
_YEAR_OF_SCENE = {s.lower(): y for y, names in SCENES.items() for s in names}
_SCALE_2001 = {"tsukuba": 16.0, "venus": 8.0}


def identify_scene_dir(scene_dir: Union[str, Path]) -> Optional[Union[int, str]]:
    """Return the layout key (2001, 2003, 2005, 2006 or ``'eval3'``) of a scene folder, or None."""
    d = Path(scene_dir)
    if not d.is_dir():
        return None
    if (d / "imL.png").is_file() and (d / "groundtruth.png").is_file():
        return 2001
    if (d / "im2.png").is_file() and (d / "disp2.png").is_file():
        return 2003
    if (d / "im0.png").is_file() and (d / "disp0GT.pfm").is_file():
        return "eval3"
    if (d / "view1.png").is_file() and (d / "disp1.png").is_file():
        year = _YEAR_OF_SCENE.get(d.name.lower())
        if year in (2005, 2006):
            return year
        if d.parent.name in ("middlebury2005", "middlebury2006"):
            return int(d.parent.name[-4:])
        return 2005 if (d / "dmin.txt").is_file() else 2006
    return None


def middlebury_scale(key: Union[int, str], scene_dir: Path, width: int) -> float:
    """Grey levels per disparity pixel of the stored ground truth (see the module table)."""
    if key == 2001:
        info = scene_dir / "info.txt"
        if info.is_file():
            try:
                return float(info.read_text().split()[0])
            except (ValueError, IndexError) as exc:
                raise DataFileError(f"'{info}' should start with the GT scale factor (e.g. '16 15')") from exc
        if scene_dir.name.lower() in _SCALE_2001:
            return _SCALE_2001[scene_dir.name.lower()]
        raise DataFileError(
            f"cannot tell the disparity scale of 2001 scene '{scene_dir}': no info.txt and unknown scene name"
        )
    if key == 2003:  # quarter size 450 px wide: x4; half: x2; full: x1
        return 4.0 if width <= 600 else (2.0 if width <= 1000 else 1.0)
    if key in (2005, 2006):  # third size ~463 px: x3; half: x2; full: x1
        return 3.0 if width <= 600 else (2.0 if width <= 1000 else 1.0)
    return 1.0  # MiddEval3 PFM: float disparity in pixels


def load_middlebury_scene(scene_dir: Union[str, Path], year: Optional[Union[int, str]] = None) -> dict:
    """Load one Middlebury scene folder as a sample dict (see the module docstring)."""
    d = Path(scene_dir)
    key = identify_scene_dir(d) if year is None else year
    if key not in LAYOUTS:
        raise DataFileError(
            f"'{d}' is not a Middlebury scene folder: expected imL.png+groundtruth.png (2001), "
            "im2.png+disp2.png (2003), view1.png+disp1.png (2005/2006) or im0.png+disp0GT.pfm (MiddEval3)"
        )
    lay = LAYOUTS[key]
    rgb = read_rgb(d / lay.colour)
    if lay.gt.endswith(".pfm"):
        gt = read_pfm(d / lay.gt)
        gt = np.where(np.isfinite(gt), gt, 0.0).astype(np.float32)
    else:
        gt = read_png_depth(d / lay.gt)
    if gt.shape != rgb.shape[:2]:
        raise DataFileError(
            f"scene '{d}': ground truth {lay.gt} is {gt.shape} but colour {lay.colour} is {rgb.shape[:2]}"
        )
    scale = middlebury_scale(key, d, gt.shape[1])
    return sample_from_arrays(
        gt.copy(), rgb, gt, scale, d.name, lay.folder, year=lay.year, path=str(d)
    )


# ----------------------------------------------------------------------------- download
_BASE = "https://vision.middlebury.edu/stereo/data"


def _download_urls(year: int, scene: str) -> str:
    if year in (2005, 2006):
        return f"{_BASE}/scenes{year}/ThirdSize/zip-2views/{scene}-2views.zip"
    if year == 2003:
        return f"{_BASE}/scenes2003/newdata/{scene.lower()}/{scene.lower()}-png-2.zip"
    raise DepthSRError(
        f"automatic download of Middlebury {year} is not supported; download the 2001 scenes by hand "
        f"from {_BASE}/scenes2001/ and store imL.png/groundtruth.png/info.txt per scene"
    )


def download_middlebury(root: Union[str, Path], year: int, scene: str, overwrite: bool = False) -> Path:
    """Fetch one scene's official archive from vision.middlebury.edu into ``root/middlebury<year>/<scene>``.

    Needs internet; never used by the tests. Only the files of this library's layout are kept.
    """
    import urllib.request

    lay = LAYOUTS[year]
    dest = Path(root) / lay.folder / scene
    if identify_scene_dir(dest) is not None and not overwrite:
        return dest
    url = _download_urls(year, scene)
    wanted = {lay.colour, lay.gt, "dmin.txt"}
    dest.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        zpath = Path(tmp) / "scene.zip"
        try:
            with urllib.request.urlopen(url, timeout=60) as r, open(zpath, "wb") as f:  # noqa: S310
                shutil.copyfileobj(r, f)
        except OSError as exc:
            raise DepthSRError(f"could not download {url}: {exc}") from exc
        with zipfile.ZipFile(zpath) as z:
            for info in z.infolist():
                base = Path(info.filename).name
                if base in wanted:
                    (dest / base).write_bytes(z.read(info))
    if identify_scene_dir(dest) is None:
        raise DataFileError(f"archive {url} did not contain {lay.colour} and {lay.gt}")
    return dest


# ----------------------------------------------------------------------------- dataset
class MiddleburyStereo(Dataset):
    """Middlebury scenes with ground truth as a torch ``Dataset`` of sample dicts.

    Args:
        root: data root holding ``middlebury<year>/<Scene>/`` folders (as ``shared/data``).
        years: which years; add ``'eval3'`` for MiddEval3 ArtL (it duplicates 2005 Art).
        scenes: optional scene names to keep (case-insensitive); default all found.
        download: fetch missing scenes of :data:`SCENES` from vision.middlebury.edu (needs internet).

    Examples:
        >>> ds = MiddleburyStereo(data_root(), years=(2005,))  # doctest: +SKIP
        >>> ds[0]['gt'].shape, ds[0]['scale']  # doctest: +SKIP
        (torch.Size([1, 370, 463]), 3.0)
    """

    def __init__(
        self,
        root: Union[str, Path],
        years: Sequence[Union[int, str]] = (2001, 2003, 2005, 2006),
        scenes: Optional[Sequence[str]] = None,
        download: bool = False,
    ) -> None:
        self.root = Path(root)
        for y in years:
            if y not in LAYOUTS:
                raise DepthSRError(f"year {y!r} is not allowed; use any of {list(LAYOUTS)}")
        keep = None if scenes is None else {s.lower() for s in scenes}
        if download:
            for y in years:
                if y in (2003, 2005, 2006):
                    for s in SCENES[y]:
                        if keep is None or s.lower() in keep:
                            download_middlebury(self.root, y, s)
        self.items = []  # list of (layout key, scene dir)
        for y in years:
            folder = self.root / LAYOUTS[y].folder
            if not folder.is_dir():
                continue
            for d in sorted(p for p in folder.iterdir() if p.is_dir()):
                if keep is not None and d.name.lower() not in keep:
                    continue
                if identify_scene_dir(d) == y:
                    self.items.append((y, d))
        if not self.items:
            raise DepthSRError(
                f"no Middlebury scenes for years={tuple(years)} scenes={scenes} under '{self.root}'; "
                "expected folders like middlebury2005/Art/{view1,disp1}.png (or pass download=True)"
            )

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, i: int) -> dict:
        y, d = self.items[i]
        return load_middlebury_scene(d, y)

    @property
    def names(self) -> list[str]:
        return [d.name for _, d in self.items]


__all__ = [
    "LAYOUTS",
    "MiddleburyLayout",
    "MiddleburyStereo",
    "SCENES",
    "download_middlebury",
    "identify_scene_dir",
    "load_middlebury_scene",
    "middlebury_scale",
]
