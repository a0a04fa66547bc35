"""Reading and writing depth maps and colour images (OpenCV, numpy; no PIL).

Depth readers return the *stored* values as a float32 ``(H, W)`` numpy array (no rescaling);
the dataset classes apply the scale conventions of ``shared/data/README.md``.

* 8/16-bit PNG: :func:`read_png_depth` (palette PNGs such as Tsukuba's ``groundtruth.png`` are
  decoded to their grey values, not palette indices), :func:`write_png_depth`.
* PFM: :func:`read_pfm`, :func:`write_pfm` (rows are stored bottom-up; the sign of the scale
  gives the byte order: negative = little-endian).
* NPY: :func:`read_npy`, :func:`write_npy`.
* Colour: :func:`read_rgb` gives float32 RGB ``(H, W, 3)`` in [0, 1].
* Sensor quirks: :func:`read_pgm16` (explicit byte order, for the little-endian NYU raw PGM),
  :func:`decode_sun_depth` (3-bit circular shift).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Tuple, Union

import cv2
import numpy as np

from torch_depth_sr.errors import DepthSRError

PathLike = Union[str, Path]


class DataFileError(DepthSRError):
    """A data file is corrupt or does not hold what was expected."""


class MissingDataFileError(DataFileError, FileNotFoundError):
    """A data file does not exist."""


def _check_exists(path: PathLike, what: str) -> Path:
    p = Path(path)
    if not p.is_file():
        raise MissingDataFileError(
            f"{what} not found: '{p}' does not exist (or is not a file). "
            "Check the data root (env TORCH_DEPTH_SR_DATA) and the dataset layout in shared/data/README.md."
        )
    return p


def _imread(path: PathLike, flags: int, what: str) -> np.ndarray:
    p = _check_exists(path, what)
    # np.fromfile + imdecode copes with non-ASCII paths, unlike cv2.imread.
    buf = np.fromfile(str(p), dtype=np.uint8)
    img = cv2.imdecode(buf, flags) if buf.size else None
    if img is None:
        raise DataFileError(
            f"could not decode {what} '{p}' ({buf.size} bytes): expected a readable image file "
            "(PNG/JPEG/PPM/PGM); the file may be truncated or corrupt"
        )
    return img


def read_png_depth(path: PathLike) -> np.ndarray:
    """Read a single-channel 8- or 16-bit depth/disparity image as float32 ``(H, W)``.

    Values are returned as stored (no scaling). Palette PNGs come back as their grey values
    (OpenCV expands the palette), and a 3-channel image is accepted only if its channels are equal.
    """
    img = _imread(path, cv2.IMREAD_UNCHANGED, "depth image")
    if img.ndim == 3:
        if img.shape[2] == 4:
            img = img[..., :3]
        if not (np.array_equal(img[..., 0], img[..., 1]) and np.array_equal(img[..., 0], img[..., 2])):
            raise DataFileError(
                f"depth image '{path}' has {img.shape[2]} differing colour channels; expected a "
                "single-channel (grey or grey-palette) 8/16-bit image"
            )
        img = img[..., 0]
    if img.dtype not in (np.uint8, np.uint16):
        raise DataFileError(f"depth image '{path}' has dtype {img.dtype}; expected uint8 or uint16")
    return img.astype(np.float32)


def write_png_depth(path: PathLike, depth: np.ndarray, bits: int = 16) -> None:
    """Write ``(H, W)`` depth as an 8- or 16-bit PNG (values rounded and clipped to the range)."""
    if bits not in (8, 16):
        raise DepthSRError(f"bits={bits} is not allowed; use 8 or 16")
    d = np.asarray(depth)
    if d.ndim != 2:
        raise DepthSRError(f"depth must be (H, W), got shape {d.shape}")
    dtype = np.uint8 if bits == 8 else np.uint16
    hi = np.iinfo(dtype).max
    out = np.clip(np.rint(np.nan_to_num(d.astype(np.float64), nan=0.0, posinf=0.0, neginf=0.0)), 0, hi).astype(dtype)
    if not cv2.imwrite(str(path), out):
        raise DataFileError(f"could not write PNG '{path}'")


def read_pfm(path: PathLike, return_scale: bool = False):
    """Read a PFM file as float32 ``(H, W)`` (``Pf``) or ``(H, W, 3)`` (``PF``), top row first.

    PFM stores rows bottom-up; they are flipped here. The header's scale sign gives the byte order
    (negative = little-endian); its magnitude is returned when ``return_scale`` is set. Infinite
    values (Middlebury's "unknown") are kept as ``inf``.
    """
    p = _check_exists(path, "PFM file")
    data = p.read_bytes()
    m = re.match(rb"(P[Ff])\s+(\d+)\s+(\d+)\s+([-+0-9.eE]+)\s", data)
    if m is None:
        raise DataFileError(
            f"'{p}' is not a PFM file: expected a header 'Pf|PF <width> <height> <scale>', "
            f"got {data[:32]!r}"
        )
    channels = 3 if m.group(1) == b"PF" else 1
    w, h = int(m.group(2)), int(m.group(3))
    scale = float(m.group(4))
    endian = "<" if scale < 0 else ">"
    n = w * h * channels
    body = data[m.end():]
    if len(body) < 4 * n:
        raise DataFileError(
            f"PFM file '{p}' is truncated: header says {w}x{h}x{channels} float32 "
            f"({4 * n} bytes), found {len(body)} bytes"
        )
    arr = np.frombuffer(body[: 4 * n], dtype=endian + "f4").astype(np.float32)
    arr = arr.reshape((h, w, channels) if channels == 3 else (h, w))
    arr = np.ascontiguousarray(arr[::-1])
    return (arr, abs(scale)) if return_scale else arr


def write_pfm(path: PathLike, array: np.ndarray, scale: float = 1.0) -> None:
    """Write ``(H, W)`` or ``(H, W, 3)`` float data as little-endian PFM (rows bottom-up)."""
    a = np.asarray(array, dtype=np.float32)
    if a.ndim == 2:
        tag = b"Pf"
    elif a.ndim == 3 and a.shape[2] == 3:
        tag = b"PF"
    else:
        raise DepthSRError(f"write_pfm expects (H, W) or (H, W, 3), got shape {a.shape}")
    if scale <= 0:
        raise DepthSRError(f"scale must be positive (the sign encodes byte order), got {scale}")
    h, w = a.shape[:2]
    header = tag + f"\n{w} {h}\n{-abs(scale):g}\n".encode()
    body = np.ascontiguousarray(a[::-1]).astype("<f4").tobytes()
    Path(path).write_bytes(header + body)


def read_npy(path: PathLike) -> np.ndarray:
    """Read a 2-D ``.npy`` depth map as float32 (a trailing singleton channel is dropped)."""
    p = _check_exists(path, "NPY file")
    try:
        a = np.load(str(p), allow_pickle=False)
    except Exception as exc:  # noqa: BLE001 - re-raised with context
        raise DataFileError(f"could not read NPY file '{p}': {exc}") from exc
    a = np.squeeze(a) if a.ndim == 3 and 1 in (a.shape[0], a.shape[-1]) else a
    if a.ndim != 2:
        raise DataFileError(f"NPY file '{p}' has shape {a.shape}; expected a 2-D depth map")
    return a.astype(np.float32)


def write_npy(path: PathLike, depth: np.ndarray) -> None:
    np.save(str(path), np.asarray(depth, dtype=np.float32))


def read_pgm16(path: PathLike, byteorder: str = "<") -> np.ndarray:
    """Read a binary 16-bit PGM (``P5``, maxval > 255) with an explicit byte order.

    The PGM standard says big-endian, but NYU's raw Kinect frames are little-endian
    (``byteorder='<'``), so OpenCV's reading gives wrong values for them.
    Returns uint16 ``(H, W)``.
    """
    p = _check_exists(path, "PGM file")
    data = p.read_bytes()
    m = re.match(rb"P5\s+(\d+)\s+(\d+)\s+(\d+)\s", data)
    if m is None:
        raise DataFileError(f"'{p}' is not a binary PGM: expected header 'P5 <w> <h> <maxval>', got {data[:20]!r}")
    w, h, maxval = (int(m.group(i)) for i in (1, 2, 3))
    if maxval < 256:
        raise DataFileError(f"PGM '{p}' has maxval {maxval}; read_pgm16 expects a 16-bit PGM")
    body = data[m.end():]
    if len(body) < 2 * w * h:
        raise DataFileError(f"PGM '{p}' is truncated: expected {2 * w * h} bytes of pixels, found {len(body)}")
    return np.frombuffer(body[: 2 * w * h], dtype=byteorder + "u2").reshape(h, w).astype(np.uint16)


def decode_sun_depth(raw: np.ndarray) -> np.ndarray:
    """Undo SUN RGB-D's 3-bit circular shift: ``mm = ((v >> 3) | (v << 13)) & 0xFFFF``."""
    v = np.asarray(raw).astype(np.uint32)
    return (((v >> 3) | (v << 13)) & 0xFFFF).astype(np.float32)


def read_rgb(path: PathLike) -> np.ndarray:
    """Read a colour image as float32 RGB ``(H, W, 3)`` in [0, 1] (8- or 16-bit; grey is replicated)."""
    img = _imread(path, cv2.IMREAD_UNCHANGED, "colour image")
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    elif img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    elif img.shape[2] == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    else:
        raise DataFileError(f"colour image '{path}' has {img.shape[2]} channels; expected 1, 3 or 4")
    if img.dtype == np.uint8:
        return img.astype(np.float32) / 255.0
    if img.dtype == np.uint16:
        return img.astype(np.float32) / 65535.0
    raise DataFileError(f"colour image '{path}' has dtype {img.dtype}; expected uint8 or uint16")


def read_depth(path: PathLike) -> np.ndarray:
    """Read a depth map by extension: PNG (stored values), PFM, NPY, 16-bit PGM (little-endian)."""
    ext = Path(path).suffix.lower()
    if ext == ".pfm":
        a = read_pfm(path)
        if a.ndim != 2:
            raise DataFileError(f"PFM '{path}' has 3 channels; expected a single-channel depth map")
        return a
    if ext == ".npy":
        return read_npy(path)
    if ext == ".pgm":
        return read_pgm16(path).astype(np.float32)
    if ext in (".png", ".tif", ".tiff"):
        return read_png_depth(path)
    raise DataFileError(f"unknown depth file type '{ext}' for '{path}'; expected .png, .pfm, .npy or .pgm")


def sample_from_arrays(
    depth: np.ndarray,
    rgb: np.ndarray,
    gt: "np.ndarray | None",
    scale: float,
    name: str,
    dataset: str,
    **extra,
) -> dict:
    """Pack numpy arrays into the library's sample dict of torch tensors.

    ``depth``/``gt`` are ``(H, W)``, ``rgb`` ``(H, W, 3)``. Non-finite values become 0 (missing).
    ``mask`` = ``gt > 0`` when a ground truth exists.
    """
    import torch

    def _depth_t(a):
        a = np.nan_to_num(np.asarray(a, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)
        return torch.from_numpy(np.ascontiguousarray(a))[None]  # (1, H, W)

    s = {
        "depth": _depth_t(depth),
        "rgb": torch.from_numpy(np.ascontiguousarray(np.asarray(rgb, dtype=np.float32).transpose(2, 0, 1))),  # (3, H, W)
        "scale": float(scale),
        "name": str(name),
        "dataset": str(dataset),
    }
    if gt is not None:
        g = _depth_t(gt)
        s["gt"] = g
        s["mask"] = (g > 0).to(torch.float32)
    s.update(extra)
    return s


__all__ = [
    "DataFileError",
    "MissingDataFileError",
    "decode_sun_depth",
    "read_depth",
    "read_npy",
    "read_pfm",
    "read_pgm16",
    "read_png_depth",
    "read_rgb",
    "sample_from_arrays",
    "write_npy",
    "write_pfm",
    "write_png_depth",
]
