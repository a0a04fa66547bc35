"""Readers for the guided depth super-resolution test sets of DKN/FDSR/DCTNet (``guided_dsr_testsets_dctnet``).

Layout (data README, section 3), one folder per set under ``<data root>/guided_dsr_testsets_dctnet``:

============================ ============================================ ========================== ==========
set                          depth file                                   colour file                units
============================ ============================================ ========================== ==========
``Middlebury`` (20)          ``Depth/Middlebury_NN_output_depth.png`` u8  ``RGB/Middlebury_NN_output_color.png``  grey levels
``Lu`` (6)                   ``Depth/RGBD_0N_output_depth.png`` u8        ``RGB/RGBD_0N_ouput_color.png`` ("ouput")  grey levels
``NYUDepthv2_Test`` (3)      ``Depth/<n>.npy`` float32 metres             ``RGB/<n>.jpg``            metres
``RGBDD`` (405)              ``Depth/<ts>_HR_gt.png`` uint16 mm           ``RGB/<ts>_RGB.jpg``       metres (mm / 1000)
``RGBDD_Test_Realscene`` (3) as RGBDD, plus ``DepthLR/<ts>_LR_fill_depth.png`` (uint16 mm, 192×144, the real
                             phone-ToF input)                                                        metres
============================ ============================================ ========================== ==========

Every image is returned in the units of the benchmark protocol (``shared/docs/benchmark.md``, track ``gdsr``,
step 1): PNG grey levels for Middlebury and Lu, metres for NYU and RGB-D-D. The RMSE units (cm for the metre
sets) are the evaluation's business, not the reader's.

Eleven of the twenty Middlebury files are Middlebury 2006 scenes, the project's fitting split (:data:`FITTING`);
the other nine are held out (``heldout=True``). Lu, NYU and RGB-D-D are all held out.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Optional, Sequence

import numpy as np

__all__ = ["FOLDER", "SETS", "ALIASES", "UNITS", "FITTING", "MIDDLEBURY_SCENES", "GDSRImage", "set_folder",
           "resolve_set", "list_names", "gdsr_images"]

FOLDER = "guided_dsr_testsets_dctnet"
SETS = ("Middlebury", "Lu", "NYUDepthv2_Test", "RGBDD", "RGBDD_Test_Realscene")
ALIASES = {"middlebury": "Middlebury", "lu": "Lu", "nyu": "NYUDepthv2_Test", "nyudepthv2_test": "NYUDepthv2_Test",
           "nyuv2": "NYUDepthv2_Test", "rgbdd": "RGBDD", "rgb-d-d": "RGBDD", "rgbdd_test_realscene": "RGBDD_Test_Realscene",
           "realscene": "RGBDD_Test_Realscene", "rgbdd_realscene": "RGBDD_Test_Realscene"}
UNITS = {"Middlebury": "grey levels", "Lu": "grey levels", "NYUDepthv2_Test": "m", "RGBDD": "m",
         "RGBDD_Test_Realscene": "m"}

# Middlebury files of the set that are 2006 scenes (the fitting split; data README, section 3)
FITTING = frozenset({"03", "04", "05", "09", "10", "11", "12", "19", "20", "28", "29"})
# file index -> scene (data README, section 3; matched by colour image)
MIDDLEBURY_SCENES = {"02": "Art", "03": "Baby1", "04": "Baby2", "05": "Baby3", "06": "Books", "09": "Cloth1",
                     "10": "Cloth2", "11": "Cloth3", "12": "Cloth4", "13": "Cones", "14": "Dolls", "18": "Laundry",
                     "19": "Midd1", "20": "Midd2", "21": "Moebius", "24": "Reindeer", "27": "Teddy", "28": "Wood1",
                     "29": "Wood2", "30": "Venus"}


@dataclass
class GDSRImage:
    """One test image. ``depth``: (H,W) float32 ground truth in the protocol's units (:data:`UNITS`);
    ``rgb``: (H,W,3) uint8 RGB; ``depth_lr``: the real low-resolution input (RGBDD_Test_Realscene only, (h,w)
    float32, same units); ``index``: the file's key (``"03"``, ``"1000"``, a timestamp); ``scene``: the
    Middlebury scene name where known; ``heldout``: not a scene the project fits on."""

    dataset: str
    name: str
    index: str
    depth: np.ndarray
    rgb: np.ndarray
    units: str
    heldout: bool = True
    scene: Optional[str] = None
    depth_lr: Optional[np.ndarray] = None


def resolve_set(name: str) -> str:
    """Canonical folder name of a set (``"nyu"`` -> ``"NYUDepthv2_Test"``); ValueError for an unknown one."""
    if name in SETS:
        return name
    key = name.lower()
    if key in ALIASES:
        return ALIASES[key]
    raise ValueError(f"unknown gdsr set {name!r}; allowed are {list(SETS)} (or {sorted(ALIASES)})")


def set_folder(root: Path, dataset: str) -> Path:
    """``<root>/guided_dsr_testsets_dctnet/<set>``; FileNotFoundError with a hint when absent."""
    folder = Path(root) / FOLDER / resolve_set(dataset)
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder} not found; set TORCH_DEPTH_SR_DATA to the shared data folder")
    return folder


def _depth_files(folder: Path, dataset: str) -> list[Path]:
    pattern = "*.npy" if dataset == "NYUDepthv2_Test" else ("*_HR_gt.png" if dataset.startswith("RGBDD")
                                                             else "*_output_depth.png")
    return sorted((folder / "Depth").glob(pattern))


def _index(p: Path, dataset: str) -> str:
    if dataset == "NYUDepthv2_Test":
        return p.stem
    if dataset.startswith("RGBDD"):
        return p.name.split("_")[0]
    return p.name.split("_")[1]  # Middlebury_03_output_depth.png, RGBD_01_output_depth.png


def list_names(root: Path, dataset: str) -> list[str]:
    """The image keys of a set, sorted (``["02", "03", ...]``, NYU numbers, RGB-D-D timestamps)."""
    dataset = resolve_set(dataset)
    return [_index(p, dataset) for p in _depth_files(set_folder(root, dataset), dataset)]


def _one(paths: list[Path], what: str, folder: Path) -> Path:
    if len(paths) != 1:
        raise FileNotFoundError(f"expected one {what} in {folder}; found {[p.name for p in paths]}")
    return paths[0]


def _read_png(path: Path) -> np.ndarray:
    import cv2

    a = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if a is None:
        raise FileNotFoundError(f"could not read {path}")
    return a


def gdsr_images(root: Path, dataset: str, only: Optional[Sequence[str]] = None,
                max_images: Optional[int] = None) -> Iterator[GDSRImage]:
    """Yield the images of one set, sorted by file name.

    ``only``: keep these keys (``"03"``, ``"1000"``, a timestamp). ``max_images``: keep that many, evenly spaced
    over the sorted list (first and last included), for a quicker deterministic subset of a large set (RGB-D-D).
    """
    dataset = resolve_set(dataset)
    folder = set_folder(root, dataset)
    files = _depth_files(folder, dataset)
    if only:
        wanted = {str(o) for o in only}
        files = [p for p in files if _index(p, dataset) in wanted]
    if max_images is not None and 0 < max_images < len(files):
        keep = np.unique(np.round(np.linspace(0, len(files) - 1, max_images)).astype(int))
        files = [files[i] for i in keep]
    for p in files:
        idx = _index(p, dataset)
        if dataset == "NYUDepthv2_Test":
            depth = np.load(p).astype(np.float32)  # metres, filled
            colour = folder / "RGB" / f"{idx}.jpg"
        elif dataset.startswith("RGBDD"):
            depth = _read_png(p).astype(np.float32) / 1000  # uint16 mm -> m
            colour = folder / "RGB" / f"{idx}_RGB.jpg"
        else:
            depth = _read_png(p)
            depth = (depth[..., 0] if depth.ndim == 3 else depth).astype(np.float32)
            prefix = p.name.split("_")[0]
            colour = _one(sorted((folder / "RGB").glob(f"{prefix}_{idx}_*")), f"colour image for {p.name}",
                          folder / "RGB")  # Lu's files say "ouput"
        bgr = _read_png(colour)
        rgb = np.ascontiguousarray(bgr[..., ::-1])
        if rgb.shape[:2] != depth.shape:
            raise ValueError(f"{colour} is {rgb.shape[:2]} but its depth {p} is {depth.shape}")
        lr = None
        if dataset == "RGBDD_Test_Realscene":
            lr = _read_png(folder / "DepthLR" / f"{idx}_LR_fill_depth.png").astype(np.float32) / 1000
        yield GDSRImage(dataset=dataset, name=f"{dataset}_{idx}", index=idx, depth=depth, rgb=rgb,
                        units=UNITS[dataset], heldout=not (dataset == "Middlebury" and idx in FITTING),
                        scene=MIDDLEBURY_SCENES.get(idx) if dataset == "Middlebury" else None, depth_lr=lr)
