"""Reading and writing depth maps and colour images (OpenCV, numpy; no PIL).

Depth readers return the *stored* values as a float32 ``(H, W)`` numpy array (no rescaling);
the dataset classes apply the scale conventions of ``shared/data/README.md``.

* 8/16-bit PNG: :func:`read_png_depth` (palette PNGs such as Tsukuba's ``groundtruth.png`` are
  decoded to their grey values, not palette indices), :func:`write_png_depth`.
* PFM: :func:`read_pfm`, :func:`write_pfm` (rows are stored bottom-up; the sign of the scale
  gives the byte order: negative = little-endian).
* NPY: :func:`read_npy`, :func:`write_npy`.
* Any depth file as stored (uint8/uint16 PNG, float32 PFM, any NPY dtype, ...): :func:`read_depth_stored`;
  :func:`write_depth` writes the format of the path's suffix, exactly the given dtype or not at all
  (:func:`depth_suffixes_for` lists the formats that hold a dtype).
* Every writer replaces its file atomically (a temporary file next to it, then ``os.replace``).
* Colour: :func:`read_rgb` gives float32 RGB ``(H, W, 3)`` in [0, 1].
* Sensor quirks: :func:`read_pgm16` (explicit byte order, for the little-endian NYU raw PGM),
  :func:`decode_sun_depth` (3-bit circular shift).
"""

from __future__ import annotations

import contextlib
import functools
import io
import os
import re
import stat
import tempfile
from pathlib import Path
from typing import Tuple, Union

import cv2
import numpy as np
from numpy.typing import DTypeLike

from torch_depth_sr.errors import DepthSRError, DTypeError

PathLike = Union[str, Path]

DEPTH_SUFFIXES = (".png", ".pfm", ".npy", ".pgm", ".tif", ".tiff")  # read by read_depth and written by write_depth


class DataFileError(DepthSRError):
    """A data file is corrupt or does not hold what was expected."""


class MissingDataFileError(DataFileError, FileNotFoundError):
    """A data file does not exist."""


def _check_exists(path: PathLike, what: str) -> Path:
    p = Path(path)
    if not p.is_file():
        state = "is a folder, not a file" if p.is_dir() else "does not exist"
        raise MissingDataFileError(f"{what} not found: '{p}' {state}.{_data_hint(p)}")
    return p


def _data_hint(p: Path) -> str:
    """Advice about the benchmark data root, only for files under it (not for a user's own files)."""
    from torch_depth_sr._data_root import data_root

    try:
        p.resolve().relative_to(data_root().resolve())
    except (ValueError, OSError):
        return ""
    return " Check the data root (env TORCH_DEPTH_SR_DATA) and the dataset layout in shared/data/README.md."


@contextlib.contextmanager
def _native_stderr(lines: list):
    """Collect what C libraries print on file descriptor 2 while the block runs, into ``lines``.

    libpng prints its errors ("libpng error: ...") and OpenCV its warnings straight to fd 2, where Python
    cannot catch them; the text becomes part of the error message instead. Output of other threads during
    the block is collected too, so keep the block to one decode.
    """
    try:
        saved = os.dup(2)
    except OSError:  # no fd 2 (e.g. a windowless process): nothing to collect
        yield
        return
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            lines.extend(ln for ln in tmp.read().decode(errors="replace").splitlines() if ln.strip())


def _native_reason(lines: list) -> str:
    """The last native message without its prefix ('libpng error: ', '[ WARN:0@0.1] global file.cpp:12 fn ')."""
    if not lines:
        return ""
    last = re.sub(r"^\[\s*\w+:[^\]]*\]\s*(global\s+\S+\s+\S+\s+)?", "", lines[-1].strip())
    return re.sub(r"^libpng error:\s*", "", last)


def _imread(path: PathLike, flags: int, what: str) -> np.ndarray:
    p = _check_exists(path, what)
    # np.fromfile + imdecode copes with non-ASCII paths, unlike cv2.imread.
    buf = np.fromfile(str(p), dtype=np.uint8)
    native: list = []
    with _native_stderr(native):
        img = cv2.imdecode(buf, flags) if buf.size else None
    if img is None:
        reason = "the file is empty" if not buf.size else (_native_reason(native) or "not a readable image")
        raise DataFileError(
            f"could not decode {what} '{p}' ({buf.size} bytes): {reason}; expected a PNG/TIFF/PPM/PGM/JPEG "
            "image, the file may be truncated or corrupt"
        )
    return img


def read_png_depth(path: PathLike) -> np.ndarray:
    """Read a single-channel 8- or 16-bit depth/disparity image as float32 ``(H, W)``.

    Values are returned as stored (no scaling). Palette PNGs come back as their grey values
    (OpenCV expands the palette), and a 3-channel image is accepted only if its channels are equal.
    """
    img = _read_image_depth(path)
    if img.dtype not in (np.uint8, np.uint16):
        raise DataFileError(f"depth image '{path}' has dtype {img.dtype}; expected uint8 or uint16")
    return img.astype(np.float32)


def _read_image_depth(path: PathLike) -> np.ndarray:
    """A single-channel image (PNG, TIFF) with its stored dtype; equal colour channels count as one."""
    img = _imread(path, cv2.IMREAD_UNCHANGED, "depth image")
    if img.ndim == 3:
        if img.shape[2] == 4:
            img = img[..., :3]
        if not (np.array_equal(img[..., 0], img[..., 1]) and np.array_equal(img[..., 0], img[..., 2])):
            raise DataFileError(
                f"depth image '{path}' has {img.shape[2]} differing colour channels; expected a "
                "single-channel (grey or grey-palette) 8/16-bit image"
            )
        img = np.ascontiguousarray(img[..., 0])
    return img


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
    atomic_write_bytes(path, _png_bytes(out, path))


def _png_bytes(a: np.ndarray, path: PathLike = "") -> bytes:
    ok, buf = cv2.imencode(".png", a)
    if not ok:
        raise DataFileError(f"could not encode PNG '{path}'")
    return buf.tobytes()


def read_pfm(path: PathLike, return_scale: bool = False) -> Union[np.ndarray, Tuple[np.ndarray, float]]:
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
    atomic_write_bytes(path, _pfm_bytes(np.asarray(array, dtype=np.float32), scale))


def _pfm_bytes(a: np.ndarray, scale: float = 1.0) -> bytes:
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
    return header + np.ascontiguousarray(a[::-1]).astype("<f4").tobytes()


def read_npy(path: PathLike) -> np.ndarray:
    """Read a 2-D ``.npy`` depth map as float32 (a trailing singleton channel is dropped)."""
    return _load_npy(path).astype(np.float32)


def _load_npy(path: PathLike) -> np.ndarray:
    """A 2-D numeric ``.npy`` map with its stored dtype (byte order included)."""
    p = _check_exists(path, "NPY file")
    try:
        a = np.load(str(p), allow_pickle=False)
    except Exception as exc:  # noqa: BLE001 - re-raised with context
        raise DataFileError(f"could not read NPY file '{p}': {exc}") from exc
    if not isinstance(a, np.ndarray):  # an .npz archive saved under a .npy name
        raise DataFileError(f"'{p}' is an NPZ archive, not an NPY array; save one 2-D array with numpy.save")
    if a.dtype.kind not in "uif":
        raise DataFileError(f"NPY file '{p}' has dtype {a.dtype}; expected a numeric depth map (integer or float)")
    a = np.squeeze(a) if a.ndim == 3 and 1 in (a.shape[0], a.shape[-1]) else a
    if a.ndim != 2:
        raise DataFileError(f"NPY file '{p}' has shape {a.shape}; expected a 2-D depth map")
    return a


def write_npy(path: PathLike, depth: np.ndarray) -> None:
    """Write ``depth`` as ``.npy`` with its own dtype, at exactly ``path`` (no ``.npy`` is appended)."""
    atomic_write_bytes(path, _npy_bytes(np.asarray(depth)))


def _npy_bytes(a: np.ndarray) -> bytes:
    f = io.BytesIO()
    np.save(f, a, allow_pickle=False)
    return f.getvalue()


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
    """Read a depth map by extension as float32: PNG/TIFF (stored values), PFM, NPY, 16-bit PGM (little-endian)."""
    return read_depth_stored(path).astype(np.float32)


def read_depth_stored(path: PathLike) -> np.ndarray:
    """Read a depth map by extension with the dtype it was stored in.

    PNG: uint8 or uint16; TIFF: what OpenCV reads (uint8/16, int16/32, float32/64); PFM: float32 (``inf``
    kept); NPY: its own dtype and byte order (a singleton channel is dropped); PGM: 16-bit little-endian.
    """
    ext = Path(path).suffix.lower()
    if ext == ".pfm":
        a = read_pfm(path)
        if a.ndim != 2:
            raise DataFileError(f"PFM '{path}' has 3 channels; expected a single-channel depth map")
        return a
    if ext == ".npy":
        return _load_npy(path)
    if ext == ".pgm":
        return read_pgm16(path)
    if ext in (".png", ".tif", ".tiff"):
        img = _read_image_depth(path)
        if img.dtype.kind not in "uif" or (ext == ".png" and img.dtype not in (np.uint8, np.uint16)):
            raise DataFileError(f"depth image '{path}' has dtype {img.dtype}; expected a numeric depth map")
        return img
    raise DataFileError(f"unknown depth file type '{ext}' for '{path}'; expected {', '.join(DEPTH_SUFFIXES)}")


def depth_suffixes_for(dtype: DTypeLike) -> list[str]:
    """The suffixes :func:`write_depth` can write ``dtype`` to without changing it, e.g. ``['.npy', '.pfm', ...]``."""
    return [s for s in DEPTH_SUFFIXES if _holds(s, np.dtype(dtype))]


def _holds(suffix: str, dt: np.dtype) -> bool:
    native = dt.newbyteorder("=")  # byte order is the format's business (NPY keeps it)
    if suffix == ".npy":
        return dt.kind in "uif"
    if suffix == ".png":
        return native in (np.dtype(np.uint8), np.dtype(np.uint16))
    if suffix == ".pfm":
        return native == np.float32
    if suffix == ".pgm":
        return native == np.uint16
    if suffix in (".tif", ".tiff"):
        return _tiff_holds(native.str)
    return False


@functools.lru_cache(maxsize=None)
def _tiff_holds(dtype_str: str) -> bool:
    """Whether this OpenCV build writes and reads back TIFF of this dtype unchanged (others fall back to 8-bit)."""
    a = np.arange(4, dtype=dtype_str).reshape(2, 2)
    native: list = []
    with _native_stderr(native):  # the 8-bit fallback is announced with a warning
        try:
            ok, buf = cv2.imencode(".tiff", a)
            b = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED) if ok else None
        except cv2.error:
            return False
    return b is not None and b.dtype == a.dtype and np.array_equal(a, b)


def encode_depth(depth: np.ndarray, suffix: str) -> bytes:
    """The bytes of ``depth`` in the format of ``suffix`` (see :data:`DEPTH_SUFFIXES`), dtype unchanged.

    Raises:
        DepthSRError: an unknown suffix, or a 3-D or larger map for an image format.
        DTypeError: a dtype the format cannot hold (float in PNG, integers in PFM); the message names those that can.
    """
    a, ext = np.asarray(depth), suffix.lower()
    if ext not in DEPTH_SUFFIXES:
        raise DepthSRError(f"cannot write depth as '{suffix}'; allowed are {', '.join(DEPTH_SUFFIXES)} "
                           "(lossy formats such as JPEG cannot hold depth)")
    if not _holds(ext, a.dtype):
        raise DTypeError(f"{ext} cannot hold {a.dtype.name} depth without changing it; write it as "
                         f"{' or '.join(depth_suffixes_for(a.dtype))}")
    if ext == ".npy":
        return _npy_bytes(a)
    if a.ndim != 2:
        raise DepthSRError(f"{ext} holds a 2-D depth map; got shape {a.shape}")
    a = a.astype(a.dtype.newbyteorder("="), copy=False)
    if ext == ".pfm":
        return _pfm_bytes(a)
    if ext == ".pgm":  # little-endian, as read_pgm16 reads it (NYU's convention, not the PGM standard's)
        return f"P5\n{a.shape[1]} {a.shape[0]}\n65535\n".encode() + a.astype("<u2").tobytes()
    ok, buf = cv2.imencode(ext, a)
    if not ok:
        raise DepthSRError(f"OpenCV could not encode a {a.dtype.name} {a.shape} map as {ext}")
    return buf.tobytes()


def write_depth(path: PathLike, depth: np.ndarray) -> None:
    """Write ``depth`` in the format of ``path``'s suffix with its dtype unchanged, atomically (see encode_depth)."""
    atomic_write_bytes(path, encode_depth(depth, Path(path).suffix))


def atomic_write_bytes(path: PathLike, data: bytes) -> None:
    """Replace ``path`` by ``data`` all at once: a killed run leaves the old file or the new one, never half of one.

    The bytes go to a hidden ``.<name>.*.part`` file in the same folder (same file system), are flushed to disk,
    then renamed over ``path``. The new file gets the old one's permissions, or the umask's for a new file.
    """
    p = Path(path)
    mode = stat.S_IMODE(p.stat().st_mode) if p.is_file() else 0o666 & ~_umask()
    fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=f".{p.name}.", suffix=".part")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, p)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _umask() -> int:
    mask = os.umask(0o022)  # the only way to read it is to set it; put it back at once
    os.umask(mask)
    return mask


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
    "DEPTH_SUFFIXES",
    "DataFileError",
    "MissingDataFileError",
    "atomic_write_bytes",
    "decode_sun_depth",
    "depth_suffixes_for",
    "encode_depth",
    "read_depth",
    "read_depth_stored",
    "read_npy",
    "read_pfm",
    "read_pgm16",
    "read_png_depth",
    "read_rgb",
    "sample_from_arrays",
    "write_depth",
    "write_npy",
    "write_pfm",
    "write_png_depth",
]
