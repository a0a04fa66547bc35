r"""Data-pipeline transforms in the style of torchvision's v2 transforms.

A transform takes a whole **sample** and returns a new one:

* a ``dict`` — the keys ``"depth"``, ``"rgb"``, ``"gt"`` and ``"mask"`` are understood, every
  other key is passed through unchanged (spatial extras such as the region masks ``"holes"``,
  ``"edges"`` of :mod:`torch_depth_sr.degradations` are cropped along by
  :class:`RandomCrop`);
* a ``tuple``/``list`` — read by position as ``(depth, rgb, gt, mask)``; missing or extra
  elements are allowed and extras pass through; the same type comes back;
* a bare tensor — taken as ``depth``.

Conventions: depth is ``(H,W)``, ``(1,H,W)`` or a batch ``(B,1,H,W)``, torch or numpy, any dtype and
any unit; ``0`` or NaN means "no measurement". Every transform returns new tensors (the input is
never modified in place) of the input's dtype, device and container type (numpy results in native byte
order: a big-endian ``>u2`` depth comes back as ``uint16`` with the values of the native-order input).
Depth, ground truth and mask with fewer than two dims, or an empty height or width, raise
:class:`~torch_depth_sr.ShapeError`.

**Randomness** is drawn once per call from torch's global generator (which a ``DataLoader``
seeds differently in each worker), so ``torch.manual_seed(s)`` makes a sample reproducible; or
pass ``seed=`` to a transform to draw from a generator seeded with ``(seed, hash(sample["name"]))``
— then the result depends only on the sample, on every machine. All transforms are picklable.

Two ways to clean depth with :class:`RestoreDepth`:

1. per sample on CPU inside ``DataLoader`` workers (``Compose([..., RestoreDepth()])`` as the
   dataset transform, ``num_workers=N``): throughput scales with workers;
2. batched on a GPU after collation: ``restore = RestoreDepth(device="cuda")`` and
   ``batch = restore(batch)`` in the training loop, on ``(B,1,H,W)`` tensors.

Examples:
    >>> from torch_depth_sr.datasets.synthetic import make_scene
    >>> s = make_scene(64, 64, seed=0)
    >>> t = Compose([RandomCrop(48), AddGaussianNoise(5.0), AddHoles(), RestoreDepth(num_layers=2)])
    >>> out = t(s)
    >>> out["depth"].shape, out["rgb"].shape, out["name"]
    (torch.Size([1, 48, 48]), torch.Size([3, 48, 48]), 'synthetic_0')
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Callable, Optional, Sequence, Tuple, TypeVar, Union

import numpy as np
import torch
import torch.nn.functional as F

from ._checks import check_divisible
from ._inputs import _integer_full_scale, native_array
from .errors import DepthSRError, DTypeError, ShapeError
from .window_max import max_filter

if TYPE_CHECKING:
    from .config import RestorerConfig
    from .model import DepthRestorer

TUPLE_KEYS = ("depth", "rgb", "gt", "mask")
Range = Union[float, Tuple[float, float]]
# A sample: a dict, a (depth, rgb, gt, mask) tuple/list or a bare depth; a transform returns the same type.
SampleT = TypeVar("SampleT", bound=Union[dict, tuple, list, torch.Tensor, np.ndarray])

__all__ = [
    "AddFlyingPixels",
    "AddGaussianNoise",
    "AddHoles",
    "AddImpulses",
    "Compose",
    "Downsample",
    "RandomCrop",
    "RestoreDepth",
    "TUPLE_KEYS",
    "Transform",
]


# ---- sample handling -----------------------------------------------------------------------------
def _unpack(sample) -> Tuple[dict, Callable[[dict], Any]]:
    """Sample -> (dict view, function packing a dict back into the sample's container type)."""
    if isinstance(sample, dict):
        return dict(sample), lambda d: d
    if isinstance(sample, (tuple, list)):
        n = len(sample)
        keys = TUPLE_KEYS[:n]
        d = {k: v for k, v in zip(keys, sample)}
        extras = list(sample[len(keys):])
        kind = type(sample)

        def pack(d2, keys=keys, extras=extras, kind=kind):
            items = [d2[k] for k in keys] + extras
            return kind(items) if kind in (tuple, list) else kind(*items)

        return d, pack
    if isinstance(sample, (torch.Tensor, np.ndarray)):
        return {"depth": sample}, lambda d: d["depth"]
    raise DepthSRError(f"a sample must be a dict, tuple, list or depth tensor; got {type(sample).__name__}. "
                       "Wrap your data as {'depth': ..., 'rgb': ...} or (depth, rgb, ...).")


def _as_torch(x) -> Tuple[torch.Tensor, bool]:
    if isinstance(x, np.ndarray):
        return torch.from_numpy(np.ascontiguousarray(native_array(x))), True
    if isinstance(x, torch.Tensor):
        return x, False
    raise DepthSRError(f"expected a torch tensor or numpy array; got {type(x).__name__}.")


def _back(x: torch.Tensor, like: torch.Tensor, was_numpy: bool):
    """Float result -> the dtype of ``like`` (rounded and clipped for integer types)."""
    if not like.is_floating_point():
        info = torch.iinfo(like.dtype)
        x = torch.nan_to_num(x, nan=0.0).round().clamp(info.min, info.max)
    x = x.to(like.dtype)
    return x.numpy() if was_numpy else x


def _depth_float(d) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, bool]:
    """-> (float depth with missing = 0, measured mask (bool), original tensor, was_numpy)."""
    t, was_np = _as_torch(d)
    if t.dim() < 2:
        raise ShapeError(f"depth must be (H,W), (1,H,W) or (B,1,H,W); got shape {tuple(t.shape)}.",
                         actual=tuple(t.shape), expected="(H,W), (1,H,W) or (B,1,H,W)")
    if t.shape[-2] == 0 or t.shape[-1] == 0:  # the window filters cannot reshape or pool an empty grid
        raise ShapeError(f"depth is empty: shape {tuple(t.shape)}; its height and width must be at least 1.",
                         actual=tuple(t.shape), expected="H, W >= 1")
    if t.dtype == torch.bool or t.is_complex():  # a bool map is a mask, not a depth (nothing to degrade)
        raise DTypeError(f"depth has dtype {t.dtype}; allowed are float, unsigned or signed integer depth. A bool "
                         "map is a validity mask: pass it as sample['mask'] next to the depth.")
    f = t.to(torch.float64 if t.dtype == torch.float64 else torch.float32)
    measured = torch.isfinite(f) & (f > 0)
    f = torch.where(measured, f, torch.zeros_like(f))
    return f, measured, t, was_np


def _range(v: Range, name: str) -> Tuple[float, float]:
    lo, hi = (v, v) if isinstance(v, (int, float)) else (float(v[0]), float(v[1]))
    if not 0 <= lo <= hi:
        raise DepthSRError(f"{name} must be a number >= 0 or a (min, max) pair with 0 <= min <= max; got {v}.")
    return float(lo), float(hi)


def _fraction(v: Range, name: str) -> Tuple[float, float]:
    lo, hi = _range(v, name)
    if hi > 1:
        raise DepthSRError(f"{name} must lie in [0, 1]; got {v}.")
    return lo, hi


def _stable_hash(name) -> int:
    from .degradations import stable_hash

    return stable_hash(str(name))


class Transform:
    """Base class: ``__call__(sample)`` draws the randomness once, then transforms what it understands.

    Subclasses implement ``_params(d, g)`` (draw random parameters with generator ``g``; may be
    ``None`` = the global generator) and ``_apply(d, params)`` returning the new dict.
    """

    seed: Optional[int] = None

    def _generator(self, d: dict) -> Optional[torch.Generator]:
        if self.seed is None:
            return None
        g = torch.Generator()
        g.manual_seed((int(self.seed) * 1_000_003 + _stable_hash(d.get("name", ""))) & 0x7FFFFFFFFFFFFFFF)
        return g

    def _params(self, d: dict, g: Optional[torch.Generator]) -> dict:
        return {}

    def _apply(self, d: dict, params: dict) -> dict:  # pragma: no cover - abstract
        raise NotImplementedError

    def __call__(self, sample: SampleT) -> SampleT:
        d, pack = _unpack(sample)
        params = self._params(d, self._generator(d))
        return pack(self._apply(d, params))

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in vars(self).items() if not k.startswith("_"))
        return f"{type(self).__name__}({args})"


class Compose(Transform):
    """Apply transforms in order (each draws its own randomness once per sample).

    Args:
        transforms: a sequence of callables taking and returning a sample.
    """

    def __init__(self, transforms: Sequence[Callable]) -> None:
        self.transforms = list(transforms)

    def __call__(self, sample: SampleT) -> SampleT:
        for t in self.transforms:
            sample = t(sample)
        return sample

    def __repr__(self) -> str:
        inner = ",\n  ".join(repr(t) for t in self.transforms)
        return f"Compose([\n  {inner}\n])"


def _uniform(lo: float, hi: float, g, size=()) -> torch.Tensor:
    return lo + (hi - lo) * torch.rand(size, generator=g, dtype=torch.float64)


# ---- degradations --------------------------------------------------------------------------------
class _DepthTransform(Transform):
    key = "depth"

    def _apply(self, d: dict, params: dict) -> dict:
        if self.key not in d or d[self.key] is None:
            return d
        f, measured, orig, was_np = _depth_float(d[self.key])
        out = self._degrade(f, measured, params)
        d[self.key] = _back(out, orig, was_np)
        return d

    def _degrade(self, f, measured, params):  # pragma: no cover - abstract
        raise NotImplementedError


class AddGaussianNoise(_DepthTransform):
    """Add i.i.d. Gaussian noise to the measured depth pixels (missing pixels stay 0).

    Args:
        sigma: noise std in depth units, or a ``(min, max)`` range drawn uniformly per sample.
        clamp_min: noisy values are clamped to at least this (so a measurement stays a measurement).
        seed: see the module docstring.

    Examples:
        >>> d = torch.full((1, 4, 4), 100.0)
        >>> out = AddGaussianNoise(5.0)(d)
        >>> out.shape, bool((out != d).all())
        (torch.Size([1, 4, 4]), True)
    """

    def __init__(self, sigma: Range = 5.0, clamp_min: float = 1e-3, seed: Optional[int] = None) -> None:
        self.sigma = _range(sigma, "sigma")
        self.clamp_min, self.seed = float(clamp_min), seed

    def _params(self, d, g):
        shape = _as_torch(d["depth"])[0].shape if d.get("depth") is not None else ()
        return {"sigma": float(_uniform(*self.sigma, g)), "z": torch.randn(shape, generator=g, dtype=torch.float64)}

    def _degrade(self, f, measured, p):
        noisy = (f + p["sigma"] * p["z"].to(f.device, f.dtype)).clamp_min(self.clamp_min)
        return torch.where(measured, noisy, torch.zeros_like(f))


def _as4d(f: torch.Tensor) -> Tuple[torch.Tensor, torch.Size]:
    shape = f.shape
    return f.reshape(-1, 1, shape[-2], shape[-1]), shape  # (N, 1, H, W)


def _edge_band(f: torch.Tensor, measured: torch.Tensor, threshold: float, radius: int) -> torch.Tensor:
    """Measured pixels within ``radius`` px of a depth jump larger than ``threshold`` (depth units)."""
    x, shape = _as4d(f)
    m, _ = _as4d(measured.to(f.dtype))
    dx = (x[..., :, 1:] - x[..., :, :-1]).abs() * (m[..., :, 1:] * m[..., :, :-1])
    dy = (x[..., 1:, :] - x[..., :-1, :]).abs() * (m[..., 1:, :] * m[..., :-1, :])
    jump = torch.zeros_like(x)
    jump[..., :, 1:] = torch.maximum(jump[..., :, 1:], dx)
    jump[..., :, :-1] = torch.maximum(jump[..., :, :-1], dx)
    jump[..., 1:, :] = torch.maximum(jump[..., 1:, :], dy)
    jump[..., :-1, :] = torch.maximum(jump[..., :-1, :], dy)
    edge = (jump > threshold).to(f.dtype)
    if radius > 0:
        edge = max_filter(edge, 2 * radius + 1)
    return (edge > 0).reshape(shape) & measured


def _choose(candidates: torch.Tensor, fraction: float, g, total: Optional[int] = None) -> torch.Tensor:
    """Boolean mask of ``round(fraction · count)`` candidate pixels drawn without replacement."""
    flat = candidates.reshape(-1).cpu()
    idx = torch.nonzero(flat).flatten()
    n = min(int(round(fraction * (idx.numel() if total is None else total))), idx.numel())
    out = torch.zeros(flat.numel(), dtype=torch.bool)
    if n > 0:
        out[idx[torch.randperm(idx.numel(), generator=g)[:n]]] = True
    return out.reshape(candidates.shape).to(candidates.device)


class AddHoles(_DepthTransform):
    """Remove measurements (set to 0) like a depth sensor: dropouts, blobs and edge shadows.

    Args:
        dropout: share of all pixels dropped singly (or a ``(min, max)`` range).
        blob_coverage: share of the image covered by filled ellipses (or a range).
        blob_axes: ``(min, max)`` full ellipse axis lengths in pixels.
        edge_fraction: share of the edge band (pixels near depth jumps) removed — the
            shadows an active sensor leaves at occlusions (or a range).
        edge_threshold: a depth jump larger than this (depth units) is an edge.
        edge_radius: edge band half-width in pixels.
        seed: see the module docstring.
    """

    def __init__(self, dropout: Range = 0.03, blob_coverage: Range = 0.04, blob_axes: Tuple[float, float] = (3.0, 12.0),
                 edge_fraction: Range = 0.3, edge_threshold: float = 4.0, edge_radius: int = 2,
                 seed: Optional[int] = None) -> None:
        self.dropout = _fraction(dropout, "dropout")
        self.blob_coverage = _fraction(blob_coverage, "blob_coverage")
        if not 0 < blob_axes[0] <= blob_axes[1]:
            raise DepthSRError(f"blob_axes must be (min, max) with 0 < min <= max; got {blob_axes}.")
        self.blob_axes = (float(blob_axes[0]), float(blob_axes[1]))
        self.edge_fraction = _fraction(edge_fraction, "edge_fraction")
        self.edge_threshold, self.edge_radius, self.seed = float(edge_threshold), int(edge_radius), seed

    def _params(self, d, g):
        if d.get("depth") is None:
            return {}
        f, measured, _, _ = _depth_float(d["depth"])
        h, w = f.shape[-2:]
        p = {k: float(_uniform(*getattr(self, k), g)) for k in ("dropout", "blob_coverage", "edge_fraction")}
        holes = _choose(torch.ones_like(measured), p["dropout"], g)
        band = _edge_band(f, measured, self.edge_threshold, self.edge_radius)
        holes |= _choose(band, p["edge_fraction"], g)
        # blobs: ellipses until the expected union covers the target (one image-sized mask, shared over a batch)
        mean_area = math.pi / 4 * (sum(self.blob_axes) / 2) ** 2
        n = int(math.ceil(p["blob_coverage"] * h * w / mean_area * 1.15)) if p["blob_coverage"] > 0 else 0
        blobs = torch.zeros(h, w, dtype=torch.bool)
        if n > 0:
            ax = _uniform(*self.blob_axes, g, (n, 2)) / 2  # (n, 2) half axes
            ang = _uniform(0.0, math.pi, g, (n,))
            cy, cx = _uniform(0, h, g, (n,)), _uniform(0, w, g, (n,))
            yy, xx = torch.meshgrid(torch.arange(h, dtype=torch.float64) + 0.5,
                                    torch.arange(w, dtype=torch.float64) + 0.5, indexing="ij")  # (H, W)
            for i in range(n):
                r = int(math.ceil(float(ax[i].max()))) + 1
                y0, y1 = max(0, int(cy[i]) - r), min(h, int(cy[i]) + r + 1)
                x0, x1 = max(0, int(cx[i]) - r), min(w, int(cx[i]) + r + 1)
                if y0 >= y1 or x0 >= x1:
                    continue
                dy, dx = yy[y0:y1, x0:x1] - cy[i], xx[y0:y1, x0:x1] - cx[i]
                c, s = math.cos(float(ang[i])), math.sin(float(ang[i]))
                u, v = c * dx + s * dy, -s * dx + c * dy
                blobs[y0:y1, x0:x1] |= (u / ax[i, 0]) ** 2 + (v / ax[i, 1]) ** 2 <= 1.0
        p["holes"] = holes | blobs.to(holes.device)
        return p

    def _degrade(self, f, measured, p):
        return torch.where(p["holes"].to(f.device), torch.zeros_like(f), f)


class AddFlyingPixels(_DepthTransform):
    """Flying pixels at depth edges: ``t·min + (1−t)·max`` of the 5×5 measured neighbourhood, t ~ U(0,1).

    Args:
        fraction: share of the edge band made flying (or a range).
        edge_threshold, edge_radius: the edge band, as in :class:`AddHoles`.
        seed: see the module docstring.
    """

    def __init__(self, fraction: Range = 0.3, edge_threshold: float = 4.0, edge_radius: int = 2,
                 seed: Optional[int] = None) -> None:
        self.fraction = _fraction(fraction, "fraction")
        self.edge_threshold, self.edge_radius, self.seed = float(edge_threshold), int(edge_radius), seed

    def _params(self, d, g):
        if d.get("depth") is None:
            return {}
        f, measured, _, _ = _depth_float(d["depth"])
        band = _edge_band(f, measured, self.edge_threshold, self.edge_radius)
        flying = _choose(band, float(_uniform(*self.fraction, g)), g)
        return {"flying": flying, "t": torch.rand(f.shape, generator=g, dtype=torch.float64)}

    def _degrade(self, f, measured, p):
        x, shape = _as4d(f)
        m, _ = _as4d(measured)
        big = torch.finfo(f.dtype).max
        nmax = max_filter(torch.where(m, x, torch.full_like(x, -big)), 5).reshape(shape)
        nmin = -max_filter(torch.where(m, -x, torch.full_like(x, -big)), 5).reshape(shape)
        t = p["t"].to(f.device, f.dtype)
        flying = torch.minimum(torch.maximum(t * nmin + (1 - t) * nmax, nmin), nmax)  # rounding-safe
        return torch.where(p["flying"].to(f.device), flying, f)


class AddImpulses(_DepthTransform):
    """Impulse outliers: a share of the pixels set uniformly within [min, max] of the measured depth.

    Args:
        fraction: share of all pixels (or a range).
        seed: see the module docstring.
    """

    def __init__(self, fraction: Range = 0.005, seed: Optional[int] = None) -> None:
        self.fraction, self.seed = _fraction(fraction, "fraction"), seed

    def _params(self, d, g):
        if d.get("depth") is None:
            return {}
        f, _, _, _ = _depth_float(d["depth"])
        return {"where": _choose(torch.ones(f.shape, dtype=torch.bool), float(_uniform(*self.fraction, g)), g),
                "u": torch.rand(f.shape, generator=g, dtype=torch.float64)}

    def _degrade(self, f, measured, p):
        if not measured.any():
            return f
        vals = f[measured]
        lo, hi = vals.min(), vals.max()
        imp = lo + (hi - lo) * p["u"].to(f.device, f.dtype)
        return torch.where(p["where"].to(f.device), imp, f)


class Downsample(_DepthTransform):
    """Downsample the depth by an integer ``factor`` (guided upsampling inputs).

    ``kernel="area"`` averages the measured pixels of each ``factor×factor`` cell (a cell with none stays
    missing); ``kernel="bicubic"`` is the antialiased bicubic resize of the guided super-resolution protocol
    (Pillow's, as DKN/FDSR/DCTNet degrade their inputs), normalised by the resized measurement mask so that holes
    do not pull values towards 0; a low-resolution pixel whose kernel mass lies mostly (≥ half) on missing pixels
    stays missing. ``rgb``, ``gt`` and ``mask`` keep their resolution, so the restorer infers the factor.

    Args:
        factor: integer >= 1; H and W must be multiples of it (crop first).
        kernel: ``"area"`` or ``"bicubic"``.
    """

    KERNELS = ("area", "bicubic")

    def __init__(self, factor: int = 4, kernel: str = "area") -> None:
        if int(factor) != factor or factor < 1:
            raise DepthSRError(f"factor must be an integer >= 1; got {factor}.")
        if kernel not in self.KERNELS:
            raise DepthSRError(f"kernel={kernel!r}; allowed are {self.KERNELS}.")
        self.factor, self.kernel = int(factor), kernel

    def _degrade(self, f, measured, p):
        s = self.factor
        check_divisible(f, "depth", s, f"Downsample(factor={s}) (crop first: RandomCrop)")
        x, shape = _as4d(f)
        m, _ = _as4d(measured.to(f.dtype))
        if self.kernel == "area":
            num, den = F.avg_pool2d(x * m, s), F.avg_pool2d(m, s)
            keep = den > 0
        else:
            size = (x.shape[-2] // s, x.shape[-1] // s)
            num, den = (F.interpolate(v, size=size, mode="bicubic", antialias=True, align_corners=False)
                        for v in (x * m, m))
            keep = den >= 0.5
        out = torch.where(keep, num / den.clamp_min(1e-12), torch.zeros_like(num))
        return out.reshape(*shape[:-2], *out.shape[-2:])


class RandomCrop(Transform):
    """Crop every spatial entry of a sample at the same place (depth, rgb, gt, mask, region masks).

    The crop is chosen on the largest grid among ``rgb``/``gt``/``depth``; entries whose last two
    dims are a ``1/s`` fraction of it (low-resolution depth) are cropped at the matching place
    (the offsets are rounded to multiples of ``s``). Entries of any other size pass through.

    Numpy colour may be ``H×W×3`` (as OpenCV and :func:`~torch_depth_sr.restore_depth` read it); it is cropped
    in its first two dims. An understood entry with fewer than two dims raises :class:`~torch_depth_sr.ShapeError`.

    Args:
        size: ``int`` or ``(h, w)`` on the largest grid.
        seed: see the module docstring.
    """

    def __init__(self, size: Union[int, Tuple[int, int]], seed: Optional[int] = None) -> None:
        size = (size, size) if isinstance(size, int) else tuple(size)
        if len(size) != 2 or min(size) < 1:
            raise DepthSRError(f"size must be an int or (h, w) >= 1; got {size}.")
        self.size, self.seed = (int(size[0]), int(size[1])), seed

    # what each understood entry may be: at least (H, W), the two dims the crop cuts
    _LAYOUTS = {"depth": "(H,W), (1,H,W) or (B,1,H,W)", "rgb": "(3,H,W), (B,3,H,W) or H×W×3 (numpy)",
                "gt": "(H,W), (1,H,W) or (B,1,H,W)", "mask": "(H,W), (1,H,W) or (B,1,H,W), like the depth"}

    @classmethod
    def _grid(cls, d: dict) -> Tuple[int, int]:
        for k, allowed in cls._LAYOUTS.items():
            v = d.get(k)
            if isinstance(v, (torch.Tensor, np.ndarray)) and v.ndim < 2:
                raise ShapeError(f"RandomCrop crops the last two dims (H, W); sample['{k}'] has shape "
                                 f"{tuple(v.shape)} ({v.ndim} dim{'s' if v.ndim != 1 else ''}). Allowed are {allowed}.",
                                 actual=tuple(v.shape), expected=allowed)
        shapes = [_hw(k, d[k]) for k in ("rgb", "gt", "depth") if d.get(k) is not None]
        if not shapes:
            raise DepthSRError("RandomCrop needs one of 'rgb', 'gt', 'depth' in the sample.")
        return max(shapes)

    def _params(self, d, g):
        h, w = self._grid(d)
        ch, cw = self.size
        if ch > h or cw > w:
            raise ShapeError(f"crop {ch}x{cw} is larger than the sample {h}x{w}; use a smaller size.",
                             actual=(h, w), expected=f"H >= {ch} and W >= {cw}, the crop size")
        return {"grid": (h, w), "top": int(torch.randint(0, h - ch + 1, (), generator=g)),
                "left": int(torch.randint(0, w - cw + 1, (), generator=g))}

    def _apply(self, d, p):
        h, w = p["grid"]
        ch, cw = self.size
        for k, v in list(d.items()):
            if not isinstance(v, (torch.Tensor, np.ndarray)) or v.ndim < 2:
                continue
            vh, vw = _hw(k, v)
            if (vh, vw) == (h, w):
                s = 1
            elif vh and h % vh == 0 and w % vw == 0 and h // vh == w // vw:
                s = h // vh
            else:
                continue
            top, left = p["top"] // s, p["left"] // s
            rows, cols = slice(top, top + ch // s), slice(left, left + cw // s)
            crop = v[rows, cols] if _channels_last(k, v) else v[..., rows, cols]
            # numpy: a native-order copy (a big-endian crop would stop torch's default_collate)
            d[k] = np.array(crop, dtype=crop.dtype.newbyteorder("=")) if isinstance(crop, np.ndarray) else crop.clone()
        return d


def _channels_last(key: str, v: Any) -> bool:
    """Whether ``v`` is numpy colour ``H×W×3`` (the rule :class:`RestoreDepth` reads colour by)."""
    return key == "rgb" and isinstance(v, np.ndarray) and v.ndim == 3 and v.shape[-1] == 3 and v.shape[0] != 3


def _hw(key: str, v: Any) -> Tuple[int, int]:
    """The height and width of a sample entry (a tensor or array of at least 2 dims)."""
    if not isinstance(v, (torch.Tensor, np.ndarray)):
        _as_torch(v)  # raises, naming the type
    return tuple(v.shape[:2]) if _channels_last(key, v) else tuple(v.shape[-2:])


# ---- restoration -----------------------------------------------------------------------------
class RestoreDepth(Transform):
    """Replace ``sample["depth"]`` by a frozen restorer's output (no gradients, no randomness).

    Works on one sample ``(1,H,W)``/``(H,W)`` (per sample on CPU, e.g. in ``DataLoader`` workers)
    or on a collated batch ``(B,1,H,W)`` (batched, e.g. on a GPU after collation). The colour
    ``sample["rgb"]`` guides it when present; if it is ``factor`` times larger than the depth, the
    depth is upsampled. The result has the input's dtype, layout and device. ``sample["mask"]``
    (ground-truth validity) is NOT used; missing input pixels are those equal to 0 or NaN.

    Args:
        restorer: a :class:`~torch_depth_sr.DepthRestorer` (default: a new frozen one built from
            ``config``/``overrides``, or ``DepthRestorer.from_preset(preset)``, or
            ``DepthRestorer.from_pretrained(pretrained)``). When nothing names a model, each sample gets what
            :func:`~torch_depth_sr.restore_depth` runs without one: the ``default`` speed tier to denoise, the
            frozen defaults (preset ``"full"``) for guided upsampling.
        preset: a named model by :meth:`DepthRestorer.from_preset <torch_depth_sr.DepthRestorer.from_preset>`: a
            speed tier (``"fast"``, ``"default"``, ``"best"``; ``docs/speed.md``) or another named configuration
            (``"paper"``, ...); ``overrides`` apply to it.
        pretrained: name of shipped parameters (see ``DepthRestorer.from_pretrained``).
        device: where to compute (``"cuda"`` for batched GPU use); the result goes back to the
            input's device.
        keep_input: if a key name, the unrestored depth is kept under it (e.g. ``"raw_depth"``).
        with_confidence: also store the confidence map under ``"confidence"``.
        config: the :class:`~torch_depth_sr.RestorerConfig` of the new restorer (default: the defaults;
            named ones: :func:`~torch_depth_sr.config.preset_config`).
        **overrides: top-level settings of :class:`~torch_depth_sr.RestorerConfig` to change, as
            :class:`~torch_depth_sr.DepthRestorer` takes them (:meth:`RestorerConfig.replace
            <torch_depth_sr.RestorerConfig.replace>`): e.g. ``num_layers=4``, ``block_matching={"k": 10}`` (a group
            as a dict of the fields to change) or ``edge_snap=None`` (a step off); ``docs/config.md``.
    """

    def __init__(self, restorer: Optional[DepthRestorer] = None, pretrained: Optional[str] = None,
                 device: Union[str, torch.device] = "cpu", keep_input: Optional[str] = None,
                 with_confidence: bool = False, config: Optional[RestorerConfig] = None, *,
                 preset: Optional[str] = None, **overrides: Any) -> None:
        from .model import DepthRestorer

        if preset is not None and (restorer is not None or pretrained is not None or config is not None):
            raise DepthSRError("RestoreDepth: preset names the model; give no restorer, pretrained or config with it "
                               "(overrides apply to the preset).")
        if restorer is None:
            if preset is not None:
                restorer = DepthRestorer.from_preset(preset, **overrides)
            elif pretrained is not None:
                restorer = DepthRestorer.from_pretrained(pretrained)
            elif config is not None or overrides:
                restorer = DepthRestorer(config, **overrides)
        elif not isinstance(restorer, DepthRestorer):
            raise DepthSRError(f"restorer must be a DepthRestorer; got {type(restorer).__name__}.")
        if restorer is not None:
            restorer = restorer.eval()
            for p in restorer.parameters():
                p.requires_grad_(False)
            restorer = restorer.to(device)
        self.restorer = restorer  # None: restore_depth's default, per sample (on ``device``)
        self.device = torch.device(device)
        self.keep_input, self.with_confidence = keep_input, bool(with_confidence)

    def _apply(self, d, p):
        if d.get("depth") is None:
            return d
        depth, was_np = _as_torch(d["depth"])
        rgb = d.get("rgb")
        in_dev = depth.device
        dep = depth.to(self.device)
        if rgb is not None:
            rgb = _as_torch(rgb)[0]
            if rgb.dim() == 3 and rgb.shape[-1] == 3 and rgb.shape[0] != 3:  # H×W×3 (numpy uint8 style)
                rgb = rgb.permute(2, 0, 1)
            if not rgb.is_floating_point():  # 8-bit colour by 255, 16-bit (uint16) by 65535
                rgb = rgb.float() / _integer_full_scale(rgb)
            rgb = rgb.to(self.device)
        from .model import restore_depth  # the model imports nothing from here; lazily, as in __init__

        with torch.no_grad():
            res = restore_depth(dep, rgb, model=self.restorer, return_details=self.with_confidence)
        out = res.depth if self.with_confidence else res
        if self.keep_input:
            d[self.keep_input] = d["depth"]
        out = out.to(in_dev).clone()
        d["depth"] = out.numpy() if was_np else out
        if self.with_confidence:
            conf = res.confidence.to(in_dev).clone()
            d["confidence"] = conf.reshape(conf.shape[-2:]) if depth.dim() == 2 else \
                conf.reshape(*depth.shape[:-2], *conf.shape[-2:])
        return d

    def __repr__(self) -> str:
        if self.restorer is None:
            return f"RestoreDepth(model=restore_depth's default, device='{self.device}')"
        return f"RestoreDepth(num_layers={self.restorer.config.num_layers}, device='{self.device}')"
