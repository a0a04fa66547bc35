"""Training crops over the Middlebury 2006 scenes and procedural synthetic scenes.

Split policy (``shared/docs/benchmark.md``, "Splits"): trained parameters are fitted on the
Middlebury **2006** scenes and on synthetic scenes only; 2005, 2003 and 2001 are for reporting.
:class:`CropDataset` refuses other years unless ``allow_test_years=True``.

Every item is a pure function of ``(seed, index)``: the scene, crop position, degradation track,
noise level and degradation seed are drawn from ``numpy.random.default_rng([seed, index])``, so
a resumed run (or another DDP rank) sees exactly the data it would have seen.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Callable, Optional, Sequence, Tuple, Union

import numpy as np
import torch
from torch.utils.data import Dataset

from ..errors import DepthSRError

if TYPE_CHECKING:
    from ..datasets.discover import SceneRecord

KEYS = ("depth", "rgb", "gt", "mask", "name")
DEGRADATIONS = ("paper", "sensor", "mixed", "none")


def middlebury_records(root: Optional[Union[str, Path]] = None, years: Sequence[int] = (2006,),
                       scenes: Optional[Sequence[str]] = None, exclude: Sequence[str] = (),
                       allow_test_years: bool = False) -> list[SceneRecord]:
    """Scene records of ``find_scenes(root, 'paper')`` filtered by year and name."""
    from .._data_root import data_root
    from ..datasets.discover import find_scenes

    years = tuple(int(y) for y in years)
    if not allow_test_years and set(years) - {2006}:
        raise DepthSRError(f"training years {years}: only 2006 is allowed for fitting (2005, 2003 and 2001 are "
                           "the reporting split); pass allow_test_years=True to override deliberately.")
    from pathlib import Path

    root = Path(root if root is not None else data_root())
    if not root.is_dir():
        return []  # no data here: synthetic scenes only
    recs = [r for r in find_scenes(root, "paper") if r.year in years]
    if scenes:
        wanted = {s.lower() for s in scenes}
        recs = [r for r in recs if r.name.lower() in wanted]
    ex = {s.lower() for s in exclude}
    return [r for r in recs if r.name.lower() not in ex]


class CropDataset(Dataset):
    """Random degraded crops ``{"depth", "rgb", "gt", "mask", "name"}`` for training and validation.

    Args:
        root: data root holding ``middlebury2006`` (default ``data_root()``); ``None`` scenes found
            and ``synthetic > 0`` means synthetic only.
        scenes, exclude: keep / drop Middlebury scene names (e.g. hold two out for validation).
        years: Middlebury years (only 2006 unless ``allow_test_years``).
        synthetic: number of synthetic scenes (``make_scene``, seeds ``synthetic_seed + j``).
        synthetic_size: (H, W) of the synthetic scenes.
        synthetic_share: probability that an item comes from a synthetic scene (when both exist).
        crop: crop size (int or (h, w)); must be a multiple of ``scale_factor``.
        length: number of items (``len``); items are independent draws.
        degradation: ``'paper'``, ``'sensor'``, ``'mixed'`` (each item picks one, 50/50),
            ``'none'``, or a callable taking and returning a sample dict (e.g. a
            :class:`~torch_depth_sr.transforms.Compose` of degradations).
        sigma: Gaussian noise std in grey levels, a number or a ``(min, max)`` range.
        scale_factor: >1 makes guided-upsampling items: the depth is the downsampled (missing-aware) ground
            truth plus noise σ, ``rgb``/``gt``/``mask`` keep full size.
        downsample: the kernel of that downsampling, ``"area"`` or ``"bicubic"`` (the ``gdsr`` protocol's;
            :class:`~torch_depth_sr.transforms.Downsample`).
        clean_share: probability that an item gets no noise at all (σ = 0), so that one model serves clean and
            noisy input; the draw comes after the item's others, so ``0`` leaves every item as before.
        seed: base seed of the item draws.
        use_middlebury: set False for synthetic-only (no data needed).

    Examples:
        >>> ds = CropDataset(use_middlebury=False, synthetic=2, synthetic_size=(64, 64), crop=32, length=4)
        >>> s = ds[0]
        >>> sorted(s), tuple(s["depth"].shape), tuple(s["rgb"].shape)
        (['depth', 'gt', 'mask', 'name', 'rgb'], (1, 32, 32), (3, 32, 32))
    """

    def __init__(self, root: Optional[Union[str, Path]] = None, scenes: Optional[Sequence[str]] = None,
                 exclude: Sequence[str] = (), years: Sequence[int] = (2006,), synthetic: int = 32,
                 synthetic_size: Tuple[int, int] = (240, 320),
                 synthetic_share: float = 0.5, synthetic_seed: int = 0, crop: Union[int, Tuple[int, int]] = 96,
                 length: int = 1000, degradation: Union[str, Callable] = "mixed",
                 sigma: Union[float, Tuple[float, float]] = (3.0, 8.0), scale_factor: int = 1, seed: int = 0,
                 use_middlebury: bool = True, allow_test_years: bool = False, downsample: str = "area",
                 clean_share: float = 0.0) -> None:
        if isinstance(degradation, str) and degradation not in DEGRADATIONS:
            raise DepthSRError(f"degradation={degradation!r}; allowed are {DEGRADATIONS} or a callable.")
        self.crop = (crop, crop) if isinstance(crop, int) else (int(crop[0]), int(crop[1]))
        self.scale_factor = int(scale_factor)
        from ..transforms import Downsample

        if downsample not in Downsample.KERNELS:
            raise DepthSRError(f"downsample={downsample!r}; allowed are {Downsample.KERNELS}.")
        if not 0.0 <= float(clean_share) <= 1.0:
            raise DepthSRError(f"clean_share={clean_share!r}; allowed is a probability in [0, 1].")
        self.downsample, self.clean_share = downsample, float(clean_share)
        if self.crop[0] % self.scale_factor or self.crop[1] % self.scale_factor:
            raise DepthSRError(f"crop {self.crop} must be a multiple of scale_factor={self.scale_factor}.")
        self.records = (middlebury_records(root, years, scenes, exclude, allow_test_years)
                        if use_middlebury else [])
        self.synthetic, self.synthetic_seed = int(synthetic), int(synthetic_seed)
        self.synthetic_size = (synthetic_size, synthetic_size) if isinstance(synthetic_size, int) \
            else tuple(int(v) for v in synthetic_size)
        if not self.records and self.synthetic <= 0:
            raise DepthSRError("CropDataset has no scenes: no Middlebury 2006 scene found "
                               f"(root={root!r}, scenes={scenes}, exclude={list(exclude)}) and synthetic=0. "
                               "Point root at the data (TORCH_DEPTH_SR_DATA) or set synthetic > 0.")
        if min(self.synthetic_size) < max(self.crop) and self.synthetic > 0:
            raise DepthSRError(f"synthetic_size {self.synthetic_size} is smaller than the crop {self.crop}.")
        self.synthetic_share = float(synthetic_share) if self.records and self.synthetic > 0 else \
            (1.0 if self.synthetic > 0 else 0.0)
        self.length, self.seed = int(length), int(seed)
        self.degradation = degradation
        self.sigma = (float(sigma), float(sigma)) if isinstance(sigma, (int, float)) else tuple(map(float, sigma))
        self._cache: dict = {}

    def __len__(self) -> int:
        return self.length

    @property
    def scene_names(self) -> list:
        return [r.name for r in self.records] + [f"synthetic_{self.synthetic_seed + j}" for j in range(self.synthetic)]

    def _scene(self, key) -> dict:
        if key not in self._cache:  # per process (each DataLoader worker builds its own small cache)
            if isinstance(key, int):
                from ..datasets.synthetic import make_scene

                h, w = self.synthetic_size
                s = make_scene(h, w, seed=self.synthetic_seed + key)
            else:
                s = next(r for r in self.records if r.name == key).load()
            self._cache[key] = {k: s[k] for k in ("rgb", "gt", "mask", "name")}
        return self._cache[key]

    def __getitem__(self, index: int) -> dict:
        if not 0 <= index < self.length:
            raise IndexError(f"index {index} out of range for CropDataset of length {self.length}")
        rng = np.random.default_rng([self.seed & 0xFFFFFFFF, int(index)])
        if rng.random() < self.synthetic_share:
            scene = self._scene(int(rng.integers(self.synthetic)))
        else:
            scene = self._scene(self.records[int(rng.integers(len(self.records)))].name)
        h, w = scene["gt"].shape[-2:]
        ch, cw = self.crop
        s = self.scale_factor
        top = int(rng.integers(0, (h - ch) // s + 1)) * s
        left = int(rng.integers(0, (w - cw) // s + 1)) * s
        crop = {k: scene[k][:, top: top + ch, left: left + cw].clone() for k in ("rgb", "gt", "mask")}
        crop["name"] = f"{scene['name']}@{top},{left}"
        crop["gt"] = torch.where(crop["mask"] > 0, crop["gt"], torch.zeros_like(crop["gt"]))
        crop["depth"] = crop["gt"].clone()
        sigma = float(rng.uniform(*self.sigma))
        dseed = int(rng.integers(2 ** 31))
        track = self.degradation
        if track == "mixed":
            track = "paper" if rng.random() < 0.5 else "sensor"
        if self.clean_share > 0 and rng.random() < self.clean_share:
            sigma = 0.0
        if s > 1:
            crop = self._downsample(crop, sigma, dseed)
        elif callable(track):
            crop = track(crop)
        elif track != "none":
            from ..degradations import make_degradation

            crop = make_degradation(track, sigma=sigma, seed=dseed)(crop)
        d = crop["depth"]
        # Gaussian noise can push tiny disparities below 0; the restorer rejects negative depth, so such
        # measurements are clamped to a small positive value (they stay measurements, holes stay 0)
        crop["depth"] = torch.where(d < 0, torch.full_like(d, 1e-3), d)
        return {k: crop[k] for k in KEYS}

    def _downsample(self, crop: dict, sigma: float, dseed: int) -> dict:
        from ..transforms import Downsample

        low = Downsample(self.scale_factor, self.downsample)(crop)["depth"]
        g = torch.Generator().manual_seed(dseed)
        noisy = low + sigma * torch.randn(low.shape, generator=g)
        crop["depth"] = torch.where(low > 0, noisy.clamp_min(1e-3), torch.zeros_like(low))
        return crop


def make_datasets(root: Optional[Union[str, Path]] = None, crop: int = 96, train_length: int = 1000,
                  val_length: int = 16, val_scenes: Sequence[str] = ("Cloth4", "Wood2"), synthetic: int = 32,
                  sigma: Union[float, Tuple[float, float]] = (3.0, 8.0), val_sigma: float = 5.0,
                  scale_factor: int = 1, degradation: Union[str, Callable] = "mixed", seed: int = 0,
                  use_middlebury: bool = True, downsample: str = "area",
                  clean_share: float = 0.0) -> tuple["CropDataset", dict[str, "CropDataset"]]:
    """Train set and one validation set per track.

    Validation uses the held-out 2006 scenes ``val_scenes`` and held-out synthetic scenes (seeds
    10000+), σ = ``val_sigma``, fixed crops; training uses the other 2006 scenes and synthetic
    seeds 0..``synthetic``-1. Returns ``(train, {"paper": ds, "sensor": ds})`` (or
    ``{"x<s>": ds}`` for upsampling, plus ``"x<s>-clean"`` (σ = 0, same crops) when ``clean_share > 0``).
    """
    train = CropDataset(root, exclude=val_scenes, synthetic=synthetic, crop=crop, length=train_length,
                        degradation=degradation, sigma=sigma, scale_factor=scale_factor, seed=seed,
                        use_middlebury=use_middlebury, downsample=downsample, clean_share=clean_share)
    vsyn = max(2, synthetic // 8)
    common = dict(scenes=val_scenes, synthetic=vsyn, synthetic_seed=10_000, crop=crop, length=val_length,
                  sigma=val_sigma, scale_factor=scale_factor, seed=seed + 777,
                  use_middlebury=use_middlebury and bool(val_scenes))
    if scale_factor > 1:
        val = {f"x{scale_factor}": CropDataset(root, degradation="none", downsample=downsample, **common)}
        if clean_share > 0:
            val[f"x{scale_factor}-clean"] = CropDataset(root, degradation="none", downsample=downsample,
                                                        **{**common, "sigma": 0.0})
        return train, val
    return train, {t: CropDataset(root, degradation=t, **common) for t in ("paper", "sensor")}


__all__ = ["CropDataset", "DEGRADATIONS", "KEYS", "make_datasets", "middlebury_records"]
