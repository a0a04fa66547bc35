"""Raw RGB-D sensor frames without ground truth (``real_sensor_samples_open3d``).

* ``TUM``: ``TUM_{color,depth}.png``, uint16, metres = v / 5000, 0 = missing; registered.
* ``SUN``: ``SUN_{color.jpg,depth.png}``, uint16 with a 3-bit circular shift
  (mm = ((v >> 3) | (v << 13)) & 0xFFFF), 0 = missing; registered.
* ``NYU_raw``: ``NYU_color.ppm`` + ``NYU_depth.pgm``: raw Kinect-v1 counts stored
  little-endian despite the PGM header; 2047 = invalid; metres = 351.3 / (1092.5 - raw).
  **Not registered** to the colour image, so it is excluded from the ``real`` track.

Samples: ``depth`` (1,H,W) float32 in **metres** (0 = missing), ``rgb`` (3,H,W), ``scale`` = 1.0
(no disparity scale applies), ``units`` = ``'m'``, ``registered`` (bool), ``name``, ``dataset``,
``path``. There is no ``gt``/``mask``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional, Union

import numpy as np
from torch.utils.data import Dataset

from torch_depth_sr.datasets.io import decode_sun_depth, read_pgm16, read_png_depth, read_rgb, sample_from_arrays
from torch_depth_sr.errors import DepthSRError

DATASET = "real_sensor_samples_open3d"
FRAMES = {
    "TUM": ("TUM_color.png", "TUM_depth.png", True),
    "SUN": ("SUN_color.jpg", "SUN_depth.png", True),
    "NYU_raw": ("NYU_color.ppm", "NYU_depth.pgm", False),
}


def nyu_raw_to_metres(raw: np.ndarray) -> np.ndarray:
    """NYU toolbox conversion; 2047 and counts giving no positive depth become 0."""
    r = np.asarray(raw, dtype=np.float64)
    valid = (r != 2047) & (r < 1092.5)
    out = np.zeros_like(r)
    out[valid] = 351.3 / (1092.5 - r[valid])
    return out.astype(np.float32)


def identify_real_frame(scene_dir: Union[str, Path]) -> Optional[str]:
    d = Path(scene_dir)
    for name, (c, dep, _) in FRAMES.items():
        if (d / c).is_file() and (d / dep).is_file():
            return name
    return None


def load_real_frame(scene_dir: Union[str, Path], kind: Optional[str] = None) -> dict:
    """Load a TUM / SUN / NYU_raw frame folder as a sample dict (depth in metres)."""
    d = Path(scene_dir)
    kind = identify_real_frame(d) if kind is None else kind
    if kind not in FRAMES:
        raise DepthSRError(
            f"'{d}' holds no known sensor frame; expected one of "
            + ", ".join(f"{c}+{dep}" for c, dep, _ in FRAMES.values())
        )
    cfile, dfile, registered = FRAMES[kind]
    rgb = read_rgb(d / cfile)
    if kind == "TUM":
        depth = read_png_depth(d / dfile) / 5000.0
    elif kind == "SUN":
        from torch_depth_sr.datasets.io import _imread
        import cv2

        raw = _imread(d / dfile, cv2.IMREAD_UNCHANGED, "SUN depth image")
        depth = decode_sun_depth(raw) / 1000.0
    else:
        depth = nyu_raw_to_metres(read_pgm16(d / dfile, byteorder="<"))
    return sample_from_arrays(
        depth, rgb, None, 1.0, kind, DATASET, units="m", registered=registered, path=str(d)
    )


class RealSensorFrames(Dataset):
    """The real sensor frames; ``include_unregistered=True`` adds NYU_raw (not registered)."""

    def __init__(self, root: Union[str, Path], include_unregistered: bool = False) -> None:
        root = Path(root)
        folder = root / DATASET if (root / DATASET).is_dir() else root
        self.frames = []
        for name, (_, _, reg) in FRAMES.items():
            d = folder / name
            if identify_real_frame(d) == name and (reg or include_unregistered):
                self.frames.append((name, d))
        if not self.frames:
            raise DepthSRError(f"no sensor frames under '{root}'; expected {DATASET}/{{TUM,SUN,NYU_raw}}/")

    def __len__(self) -> int:
        return len(self.frames)

    def __getitem__(self, i: int) -> dict:
        name, d = self.frames[i]
        return load_real_frame(d, name)


__all__ = ["FRAMES", "RealSensorFrames", "identify_real_frame", "load_real_frame", "nyu_raw_to_metres"]
