"""Turn what users pass (numpy or torch, many layouts and dtypes) into model tensors and back.

Depth layouts: ``(H,W)``, ``(1,H,W)``, ``(B,1,H,W)``; dtypes float16/32/64, uint8, uint16, int32.
0 or NaN means "no measurement". Colour: ``(B,3,H,W)``/``(3,H,W)`` float in [0,1] (torch or numpy),
``H×W×3`` (numpy, RGB order) uint8, uint16 or float in [0,1], or ``(B,1,H,W)``/``H×W`` greyscale.
Numpy arrays may be big-endian (``>f4`` from a PFM, ``>u2`` from a raw 16-bit PGM) or read-only: converted,
never modified. A result comes back in native byte order with the input's kind and size (``>u2`` in, native
``uint16`` out; the values are those of the native-order input, bit for bit).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from .errors import DTypeError, InvalidDepthError, ShapeError

__all__ = ["DepthLayout", "native_array", "parse_depth", "parse_rgb", "restore_layout", "map_layout"]


@dataclass(frozen=True)
class DepthLayout:
    """How the user's depth arrived, so the result can go back the same way."""

    was_numpy: bool
    ndim: int
    dtype: Any  # numpy dtype or torch dtype
    device: torch.device


def native_array(x: np.ndarray) -> np.ndarray:
    """``x`` in native byte order and writable, copied only when it is not (torch refuses byte-swapped
    arrays and warns on read-only ones, though the library never writes to an input)."""
    if not x.dtype.isnative:
        return x.astype(x.dtype.newbyteorder("="))
    if not x.flags.writeable:
        return np.array(x)
    return x


def _as_tensor(x: Any, name: str) -> tuple[torch.Tensor, bool]:
    if isinstance(x, torch.Tensor):
        return x, False
    if isinstance(x, np.ndarray):
        if x.dtype.kind not in "fiub":
            raise DTypeError(f"{name} has numpy dtype {x.dtype}; allowed are float, unsigned/signed int or bool.")
        x = native_array(x)
        if x.dtype == np.uint16:  # torch.from_numpy supports uint16 only in recent versions; widen safely
            return torch.from_numpy(x.astype(np.int32)), True
        return torch.from_numpy(np.ascontiguousarray(x)), True
    raise DTypeError(f"{name} must be a torch.Tensor or numpy.ndarray; got {type(x).__name__}.")


def parse_depth(depth: Any, mask: Any = None, compute_dtype: torch.dtype = torch.float32
                ) -> tuple[torch.Tensor, torch.Tensor, DepthLayout]:
    """Return ``(y (B,1,H,W) float with 0 at missing, observed (B,1,H,W) float, layout)``.

    Raises:
        ShapeError: the layout is not one of the allowed ones.
        DTypeError: complex, bool or object dtypes.
        InvalidDepthError: negative or infinite depth, or a sample with no measured pixel.
    """
    orig_dtype = depth.dtype if isinstance(depth, (torch.Tensor, np.ndarray)) else None
    if isinstance(depth, np.ndarray):  # the result goes back in native byte order (``>u2`` in, uint16 out)
        orig_dtype = orig_dtype.newbyteorder("=")
    t, was_numpy = _as_tensor(depth, "depth")
    if t.dtype == torch.bool or t.is_complex():
        raise DTypeError(f"depth has dtype {t.dtype}; allowed are float16/32/64, uint8, uint16 or int32.")
    ndim = t.ndim
    if ndim == 2:
        t = t[None, None]
    elif ndim == 3:
        if t.shape[0] != 1:
            raise ShapeError(f"depth with 3 dims must be (1,H,W); got {tuple(t.shape)}. "
                             "Use (B,1,H,W) for a batch.", actual=tuple(t.shape), expected="(1,H,W)")
        t = t[None]
    elif ndim == 4:
        if t.shape[1] != 1:
            raise ShapeError(f"depth must have one channel, (B,1,H,W); got {tuple(t.shape)}.",
                             actual=tuple(t.shape), expected="(B,1,H,W)")
    else:
        raise ShapeError(f"depth must be (H,W), (1,H,W) or (B,1,H,W); got shape {tuple(t.shape)}.",
                         actual=tuple(t.shape), expected="(H,W), (1,H,W) or (B,1,H,W)")
    if t.shape[0] == 0 or t.shape[-1] == 0 or t.shape[-2] == 0:
        raise ShapeError(f"depth is empty: shape {tuple(t.shape)}.", actual=tuple(t.shape),
                         expected="B, H, W >= 1")
    y = t.to(compute_dtype)
    observed = torch.isfinite(y) & (y > 0)
    m = None if mask is None else _parse_mask(mask, y.shape, tuple(t.shape if ndim == 4 else depth.shape)).to(y.device)
    if _values_readable(y):
        _check_depth_values(y, observed, m)
    if m is not None:
        observed = observed & m
    y = torch.where(observed, y, torch.zeros_like(y))
    layout = DepthLayout(was_numpy=was_numpy, ndim=ndim, dtype=orig_dtype, device=t.device)
    return y, observed.to(compute_dtype), layout


def _parse_mask(mask: Any, shape: torch.Size, depth_shape: tuple) -> torch.Tensor:
    """Return ``mask`` as a bool tensor of ``shape`` (nonzero = measured)."""
    m, _ = _as_tensor(mask, "mask")
    if m.is_complex():
        raise DTypeError(f"mask has dtype {m.dtype}; complex masks are not allowed: use bool, integer or float "
                         "(values > 0 mean measured).")
    if m.shape[-2:] != shape[-2:] or m.numel() != shape.numel():
        raise ShapeError(f"mask must have the same shape as depth; got mask {tuple(m.shape)} and depth {depth_shape}.",
                         actual=tuple(m.shape), expected=f"{tuple(depth_shape)}, depth's shape")
    return m.reshape(shape) > 0


def _values_readable(t: torch.Tensor) -> bool:
    """Whether the input's values can be checked: not while a CUDA graph is being captured (reading a value there
    fails; the caller checks its inputs before capturing, and a replay checks nothing)."""
    return not (t.is_cuda and torch.cuda.is_current_stream_capturing())


def _check_depth_values(y: torch.Tensor, observed: torch.Tensor, mask: Any) -> None:
    """Refuse ±inf, negative values and a sample without a measured pixel (in depth, in the mask, in both), in that
    order. One read of the values on the host (on a GPU, the one wait of the depth input for the device)."""
    empty = [observed.flatten(1).sum(1) == 0]
    if mask is not None:
        empty += [mask.flatten(1).sum(1) == 0, (observed & mask).flatten(1).sum(1) == 0]
    has_inf, negative, *flags = torch.cat([torch.stack([torch.isinf(y).any(), (y < 0).any()])] + empty).tolist()
    if has_inf:
        raise InvalidDepthError("depth contains +/-inf; allowed are finite values, with 0 or NaN for "
                                "'no measurement'. Replace inf by NaN (e.g. PFM files mark unknown with inf).")
    if negative:
        raise InvalidDepthError(f"depth contains negative values (min {float(torch.nan_to_num(y).min()):g}); "
                                "allowed are depth/disparity >= 0 with 0 or NaN meaning 'no measurement'.")
    messages = ["depth sample(s) {bad} have no measured pixel (all 0 or NaN); at least one pixel > 0 is needed to "
                "restore a depth map.",
                "mask marks no pixel of sample(s) {bad} as measured (all 0 or False); values > 0 mean measured. "
                "Pass mask=None to use depth > 0 alone.",
                "mask and depth share no measured pixel in sample(s) {bad}: where the mask is nonzero the depth is 0 "
                "or NaN. Check that they belong together."]
    n = y.shape[0]
    for i, message in enumerate(messages[:len(empty)]):
        bad = [j for j, e in enumerate(flags[i * n:(i + 1) * n]) if e]
        if bad:
            raise InvalidDepthError(message.format(bad=bad))


def parse_rgb(rgb: Any, batch: int, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    """Return colour as ``(B,3,H,W)`` float in [0,1] on ``device``.

    Integer colour is scaled by its dtype's range: uint16 by 65535, other integers (uint8) by 255.
    """
    full_scale = _integer_full_scale(rgb)
    t, was_numpy = _as_tensor(rgb, "rgb")
    if t.dtype == torch.bool or t.is_complex():
        raise DTypeError(f"rgb has dtype {t.dtype}; allowed are uint8 (0..255), uint16 (0..65535) or float in [0,1].")
    is_int = not t.is_floating_point()
    if was_numpy and t.ndim == 3 and t.shape[-1] in (1, 3):
        t = t.permute(2, 0, 1)  # numpy colour is H×W×C -> (C,H,W)
    if t.ndim == 2:
        t = t[None, None]
    elif t.ndim == 3:
        t = t[None]
    if t.ndim != 4 or t.shape[1] not in (1, 3):
        raise ShapeError(f"rgb must be (B,3,H,W), (3,H,W), H×W×3 (numpy) or greyscale; got {tuple(rgb.shape)}.",
                         actual=tuple(rgb.shape), expected="(B,3,H,W), (3,H,W), H×W×3 or greyscale")
    t = t.to(device=device, dtype=dtype)
    if _values_readable(t):
        _check_rgb_range(t.detach(), is_int, full_scale, rgb.dtype)  # detached: the checks read values only
    if is_int:
        t = t / full_scale
    if t.shape[1] == 1:
        t = t.expand(-1, 3, -1, -1)
    if t.shape[0] == 1 and batch > 1:
        t = t.expand(batch, -1, -1, -1)
    if t.shape[0] != batch:
        raise ShapeError(f"rgb batch size {t.shape[0]} does not match depth batch size {batch}.",
                         actual=tuple(rgb.shape), expected=f"batch 1 or {batch}, depth's batch size")
    return t.clamp(0, 1).contiguous()


def _integer_full_scale(rgb: Any) -> float:
    """The value of white for integer colour: 65535 for uint16 (numpy or torch), else 255."""
    if isinstance(rgb, np.ndarray):
        return 65535.0 if rgb.dtype.kind == "u" and rgb.dtype.itemsize == 2 else 255.0
    return 65535.0 if getattr(rgb, "dtype", None) == getattr(torch, "uint16", object()) else 255.0


def _check_rgb_range(t: torch.Tensor, is_int: bool, full_scale: float, orig_dtype: Any) -> None:
    """Refuse non-finite colour and colour outside its range; one read of the values on the host."""
    finite, lo, hi = torch.stack([torch.isfinite(t).all().to(t.dtype), t.min(), t.max()]).tolist()
    if not finite:
        raise DTypeError("rgb contains NaN or inf; allowed are finite values in [0,1] (float) or 0..255 (uint8).")
    if is_int and (lo < 0 or hi > full_scale):
        raise DTypeError(f"integer rgb of dtype {orig_dtype} is read as {'16' if full_scale > 255 else '8'}-bit "
                         f"(0..{full_scale:g}); got values in [{lo:g}, {hi:g}]. Pass 8-bit colour as uint8, "
                         "16-bit colour as uint16, or float colour in [0,1].")
    if not is_int and (lo < -1e-3 or hi > 1 + 1e-3):
        hint = ("It looks like 16-bit colour: divide by 65535 (or pass it as uint16)." if hi > 255 + 1e-3 else
                "Divide 8-bit colour by 255 (or pass it as uint8).")
        raise DTypeError(f"float rgb must lie in [0,1]; got values in [{lo:g}, {hi:g}]. {hint}")


def restore_layout(x: torch.Tensor, layout: DepthLayout) -> Any:
    """Return ``x (B,1,H,W)`` in the user's layout, dtype, device and array type (NaN becomes 0 in an integer
    dtype: "no measurement" in integer depth). Numpy results are in native byte order: :func:`parse_depth` records
    a big-endian ``>u2`` input as ``uint16``."""
    if layout.ndim == 2:
        x = x[0, 0]
    elif layout.ndim == 3:
        x = x[0]
    x = x.to(layout.device)
    if layout.was_numpy:
        arr = x.detach().cpu().numpy()
        dt = np.dtype(layout.dtype)
        if dt.kind in "ui":
            info = np.iinfo(dt)
            arr = np.clip(np.rint(np.nan_to_num(arr, nan=0.0)), max(info.min, 0), info.max)
        return arr.astype(dt)
    dt = layout.dtype
    if not dt.is_floating_point:
        info = torch.iinfo(dt)
        x = x.nan_to_num(nan=0.0).round().clamp(max(info.min, 0), info.max)
    return x.to(dt)


def map_layout(x: torch.Tensor, layout: DepthLayout) -> Any:
    """Return a float map ``x (B,1,H,W)`` (confidence, outliers) in the user's layout and array type."""
    if layout.ndim == 2:
        x = x[0, 0]
    elif layout.ndim == 3:
        x = x[0]
    x = x.detach().to(layout.device)
    return x.cpu().numpy().astype(np.float32) if layout.was_numpy else x
