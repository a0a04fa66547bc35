"""The file plumbing that restoring files and restoring recordings share: which files are depth and colour maps,
how a depth folder pairs with a colour folder, whether an output can be written, and the conversions between what
a file stores and what the model takes."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Optional

import numpy as np
import torch

from ..errors import UsageError
from .io import DEPTH_SUFFIXES

__all__ = ["DEPTH_EXTS", "RGB_EXTS", "as_numpy", "check_writable", "describe_files", "file_identity", "pair_folders",
           "stored_layout", "to_model_input", "with_path"]

DEPTH_EXTS = DEPTH_SUFFIXES
RGB_EXTS = (".png", ".jpg", ".jpeg", ".ppm", ".bmp", ".tif", ".tiff")


def pair_folders(depth_dir: Path, rgb_dir: Path | None) -> tuple[list[Path], list[Path | None]]:
    # names starting with "." are skipped: hidden files, and the temporary files of an interrupted run
    depths = sorted(p for p in depth_dir.iterdir()
                    if p.suffix.lower() in DEPTH_EXTS and p.is_file() and not p.name.startswith("."))
    if not depths:
        raise UsageError(f"no depth files ({', '.join(DEPTH_EXTS)}) in the folder '{depth_dir}'")
    if rgb_dir is None:
        return depths, [None] * len(depths)
    rgbs = {p.stem: p for p in rgb_dir.iterdir()
            if p.suffix.lower() in RGB_EXTS and p.is_file() and not p.name.startswith(".")}
    missing = [p.name for p in depths if p.stem not in rgbs]
    if not missing:
        return depths, [rgbs[p.stem] for p in depths]
    ordered = sorted(rgbs.values())
    if len(ordered) != len(depths):
        raise UsageError(f"colour folder '{rgb_dir}' has no file named like {', '.join(missing[:3])}"
                         f"{', ...' if len(missing) > 3 else ''} and holds {len(ordered)} colour files for "
                         f"{len(depths)} depth files; pair them by name (a.png with a.jpg) or by sorted order with "
                         "equal counts")
    return depths, ordered


def file_identity(p: Path) -> Optional[tuple[int, int]]:
    """What makes two paths the same file (symlinks, hard links, ``a/../b``): its device and inode; None if absent."""
    # abspath folds "new/../b" into "b": the kernel cannot resolve it while "new" is missing, but will once the
    # output's folders are created
    for q in (p, Path(os.path.abspath(p))):
        try:
            st = q.stat()
        except OSError:
            continue
        return st.st_dev, st.st_ino
    return None


def describe_files(paths: list[Path]) -> str:
    shown = ", ".join(f"'{p}'" for p in paths[:3])
    return shown if len(paths) <= 3 else f"{len(paths)} outputs ({shown}, ...)"


def check_writable(out: Path) -> None:
    folder = out.parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent  # the folder that the missing ones will be created in
    if not folder.is_dir():
        raise UsageError(f"cannot write '{out}': '{folder}' is a file, not a folder; choose another output")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise UsageError(f"cannot write '{out}': no permission to write in the folder '{folder}'")


def with_path(e: BaseException, path: Path, text: Optional[str] = None) -> str:
    text = str(e) if text is None else text
    return text if str(path) in text else f"{path}: {text}"


def as_numpy(x: Any) -> np.ndarray:
    return x.detach().cpu().numpy() if isinstance(x, torch.Tensor) else np.asarray(x)


def to_model_input(depth: np.ndarray) -> np.ndarray:
    if not depth.dtype.isnative:  # torch reads native byte order only; the output gets the input's back
        depth = depth.astype(depth.dtype.newbyteorder("="))
    if depth.dtype.kind == "f":
        return np.where(np.isfinite(depth), depth, np.nan)  # PFM marks unknown with inf
    return depth


def stored_layout(out: np.ndarray, src: Path) -> np.ndarray:
    """An NPY map goes back with the singleton axis it was stored with, ``(1, H, W)`` or ``(H, W, 1)``."""
    if src.suffix.lower() != ".npy":
        return out
    shape = np.load(str(src), mmap_mode="r").shape
    if len(shape) == 3 and shape[0] == 1:
        return out[None]
    if len(shape) == 3 and shape[-1] == 1:
        return out[..., None]
    return out

