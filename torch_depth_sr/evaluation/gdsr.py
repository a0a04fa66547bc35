"""Track ``gdsr``: guided depth super-resolution as DKN, FDSR and DCTNet report it (``shared/docs/benchmark.md``).

``torch-depth-sr bench --track gdsr --sets Middlebury Lu --scales 4 8 16 --noise 0 5 --methods bicubic full
trained --json F`` runs, per image of each set (:mod:`torch_depth_sr.datasets.gdsr`), scale and noise level:

1. ground truth in the protocol's units (grey levels; metres for NYU and RGB-D-D), cropped at the bottom and
   right to a multiple of the scale (:func:`crop_to_multiple`);
2. the low-resolution input: Pillow's antialiased bicubic resize (mode "F") to (H/s, W/s), done by torch's
   ``interpolate(mode="bicubic", antialias=True)``, which is the same resampling (a = -0.5 cubic, support
   widened by s, window clipped and renormalised at the border; :func:`resize_pillow`); optionally i.i.d.
   Gaussian noise of ``noise`` on a 0-255 scale of the cropped ground truth's range, seeded per set, image and
   scale (:func:`add_noise`). ``RGBDD_Test_Realscene``: the real 192x144 phone-ToF depth is the input instead
   (noise, if asked, is added to it), only at scale 4;
3. methods: ``bicubic`` = Pillow's bicubic upsampling of the input to the ground truth's size (the networks'
   input, DCTNet's ``DepthLrUp``); ``full`` = the frozen :class:`~torch_depth_sr.DepthRestorer` (the defaults,
   preset ``default``) with ``degradation="bicubic"`` (the K of this protocol) plus any ``--config`` overrides
   (:func:`~torch_depth_sr.config.apply_overrides`); ``trained`` = the shipped ``from_pretrained("upsample")``
   (the frozen model plus the edge refiner, one model for every factor; ``--pretrained FOLDER`` evaluates a saved
   candidate instead);
   ``trained-x4-refined`` = ``from_pretrained("upsample-x4-refined")``, a wider refiner for ×4 only; ``trained-x4`` =
   the older ``from_pretrained("upsample-x{s}")``, a row marked not available where no such model ships. The models get the low-resolution depth in the protocol's units and
   the full-resolution colour; input values <= 0 are missing. For the real scene, whose input is 192x144 for a
   512x384 grid (factor 8/3, not an integer), the models get the input resized to 128x96 (Pillow bicubic) and
   upsample it x4; bicubic resizes 192x144 straight to 512x384, as DCTNet does;
4. RMSE over all pixels (:func:`rmse`), the mean of the per-image values: Middlebury and Lu in grey levels
   after clipping both maps to [0, 255]; NYU in cm after cropping a 6-pixel border; RGB-D-D in cm, no crop.

Rows: ``dataset``, ``image``, ``scene``, ``heldout``, ``scale``, ``noise``, ``method``, ``rmse``, ``units``,
``seconds`` (``available: False`` and ``rmse: None`` where a method does not exist for a scale). The summary
has the mean per set, scale, noise and method over all images (``subset: "all"``) and, for Middlebury, over the
nine that are not 2006 fitting scenes (``subset: "heldout"``).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Optional, TypeVar

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from ..datasets.gdsr import FOLDER, SETS, GDSRImage, gdsr_images, resolve_set
from ..errors import UsageError

if TYPE_CHECKING:
    from ..model import DepthRestorer

__all__ = ["METHODS", "REAL_SCALE", "crop_to_multiple", "resize_pillow", "add_noise", "degrade", "bicubic",
           "rmse", "make_model", "run_gdsr", "summarise_gdsr"]

METHODS = ("bicubic", "full", "trained", "trained-x4-refined", "trained-x4")
REAL_SCALE = 4  # RGBDD_Test_Realscene: the models upsample x4 (input resized to a quarter of the HR grid)
NOISE_SEED = 0
GREY_SETS = ("Middlebury", "Lu")
CM_SETS = ("NYUDepthv2_Test", "RGBDD", "RGBDD_Test_Realscene")
NYU_BORDER = 6

ArrayT = TypeVar("ArrayT", torch.Tensor, np.ndarray)


def crop_to_multiple(a: ArrayT, s: int) -> ArrayT:
    """Crop the last two axes (bottom and right) so both are divisible by ``s``."""
    h, w = a.shape[-2] // s * s, a.shape[-1] // s * s
    return a[..., :h, :w]


def resize_pillow(x: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """Pillow's ``Image.resize(size[::-1], BICUBIC)`` of a float ("F" mode) image, for (B,C,H,W) tensors.

    torch's antialiased bicubic path uses Pillow's cubic (a = -0.5), its support widened by the factor when
    shrinking, and the same border rule (the window clipped to the image, the weights renormalised); plain
    ``mode="bicubic"`` is Keys' a = -0.75 with replicated borders, which is NOT Pillow's, also when enlarging.
    """
    return F.interpolate(x, size=(int(size[0]), int(size[1])), mode="bicubic", antialias=True,
                         align_corners=False)


def add_noise(lr: torch.Tensor, noise: float, gt_range: float, name: str, seed: int = NOISE_SEED) -> torch.Tensor:
    """``lr`` + i.i.d. N(0, (noise * gt_range / 255)^2), drawn from the per-name generator (same on every run)."""
    if not noise:
        return lr
    from ..degradations import scene_rng

    z = scene_rng(seed, name).standard_normal(tuple(lr.shape)).astype(np.float32)
    return lr + float(noise) * float(gt_range) / 255.0 * torch.from_numpy(z).to(lr)


def degrade(img: GDSRImage, scale: int, noise: float = 0.0, seed: int = NOISE_SEED) -> dict:
    """The protocol's sample for one image: ``gt`` (1,1,H,W) cropped, ``lr`` (1,1,h,w) the input, ``rgb``
    (1,3,H,W) float in [0,1], ``model_lr`` / ``factor`` what a model of ours upsamples (the input itself and
    ``scale``, except for the real scene: ``lr`` resized to (H/4, W/4) and 4)."""
    s = REAL_SCALE if img.depth_lr is not None else int(scale)
    gt = crop_to_multiple(torch.from_numpy(img.depth)[None, None], s)
    h, w = gt.shape[-2:]
    rgb = torch.from_numpy(np.ascontiguousarray(img.rgb[:h, :w])).permute(2, 0, 1)[None].float() / 255
    gt_range = float(gt.max() - gt.min())
    key = f"gdsr/{img.dataset}/{img.index}/x{s}"
    if img.depth_lr is not None:  # the real low-resolution depth is the input
        lr = add_noise(torch.from_numpy(img.depth_lr)[None, None], noise, gt_range, key, seed)
        model_lr = resize_pillow(lr, (h // s, w // s))
    else:
        lr = add_noise(resize_pillow(gt, (h // s, w // s)), noise, gt_range, key, seed)
        model_lr = lr
    return {"gt": gt, "lr": lr, "rgb": rgb, "model_lr": model_lr, "factor": s}


def bicubic(lr: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """The networks' baseline: Pillow's bicubic upsampling of the low-resolution input."""
    return resize_pillow(lr, size)


def rmse(pred: torch.Tensor, gt: torch.Tensor, dataset: str) -> float:
    """RMSE over all pixels in the published units: grey levels after clipping both maps to [0, 255]
    (Middlebury, Lu); cm = m x 100 after cropping a 6-pixel border (NYU); cm, no crop (RGB-D-D)."""
    p, g = pred.double(), gt.double()
    if dataset in GREY_SETS:
        p, g = p.clamp(0, 255), g.clamp(0, 255)
    elif dataset in CM_SETS:
        p, g = p * 100, g * 100
        if dataset == "NYUDepthv2_Test":
            b = NYU_BORDER
            p, g = p[..., b:-b, b:-b], g[..., b:-b, b:-b]
    else:
        raise ValueError(f"unknown gdsr set {dataset!r}; allowed are {list(SETS)}")
    return float((p - g).square().mean().sqrt())


def make_model(method: str, scale: int, config: Optional[dict] = None, device: str = "cpu",
               pretrained: Optional[str] = None) -> Optional[DepthRestorer]:
    """The model behind a method name, or None where no such model exists (``trained-x4`` for a scale without a
    shipped ``upsample-x{scale}``). ``pretrained``: a saved model folder that ``trained`` loads instead."""
    from ..config import RestorerConfig, apply_overrides
    from ..errors import DepthSRError
    from ..model import DepthRestorer

    if method == "full":
        base = RestorerConfig(degradation="bicubic")  # then --config (which may set another degradation)
        return DepthRestorer(apply_overrides(base, config)).to(device).eval()
    if method in ("trained", "trained-x4-refined"):
        name = "upsample" if method == "trained" else "upsample-x4-refined"
        if method == "trained-x4-refined" and scale != 4 and not pretrained:
            return None
        model = DepthRestorer.load(pretrained) if pretrained else DepthRestorer.from_pretrained(name)
        return model.to(device).eval()
    if method == "trained-x4":
        try:
            return DepthRestorer.from_pretrained(f"upsample-x{scale}").to(device).eval()
        except DepthSRError:
            return None
    raise ValueError(f"unknown gdsr method {method!r}; allowed are {list(METHODS)}")


def _run_model(model, sample: dict, device: str) -> torch.Tensor:
    lr = sample["model_lr"]
    lr = torch.where(lr > 0, lr, torch.full_like(lr, float("nan")))  # <= 0 (bicubic overshoot, noise): missing
    with torch.no_grad():
        return model(lr.to(device), sample["rgb"].to(device)).cpu()


def _check(args) -> tuple[list[str], list[int], list[float], list[str]]:
    try:
        sets = [resolve_set(s) for s in (getattr(args, "sets", None) or ["Middlebury", "Lu"])]
    except ValueError as e:
        raise UsageError(str(e)) from e
    scales = [int(s) for s in (getattr(args, "scales", None) or [4, 8, 16])]
    if any(s < 2 for s in scales):
        raise UsageError(f"--scales must be whole numbers >= 2; got {scales}")
    noises = [float(n) for n in (getattr(args, "noise", None) or [0.0])]
    if any(not math.isfinite(n) or n < 0 for n in noises):
        raise UsageError(f"--noise must be finite and >= 0; got {noises}")
    methods = list(args.methods or METHODS)
    bad = [m for m in methods if m not in METHODS]
    if bad:
        raise UsageError(f"track gdsr has no method(s) {bad}; allowed are {list(METHODS)}")
    return list(dict.fromkeys(sets)), list(dict.fromkeys(scales)), list(dict.fromkeys(noises)), methods


def run_gdsr(args: argparse.Namespace, config: Optional[dict] = None) -> int:
    """``bench --track gdsr``: see the module docstring. ``config``: RestorerConfig overrides for ``full``
    (``bench`` passes its checked ``--config``)."""
    from .._data_root import data_root
    from .report import metadata, print_table

    sets, scales, noises, methods = _check(args)
    root = Path(args.data) if args.data else data_root()
    device = getattr(args, "device", "cpu") or "cpu"
    present = [d for d in sets if (root / FOLDER / d).is_dir()]
    for d in sets:
        if d not in present:
            print(f"gdsr: skipping {d}: {root / FOLDER / d} not found (set TORCH_DEPTH_SR_DATA to the shared data "
                  "folder)", file=sys.stderr)
    if not present:
        raise UsageError(f"no gdsr test set found under {root / FOLDER}; set --data or TORCH_DEPTH_SR_DATA to the "
                         "shared data folder")
    images = {d: list(gdsr_images(root, d, only=getattr(args, "scenes", None),
                                  max_images=getattr(args, "max_images", None))) for d in present}
    jobs = []  # (image, scale) pairs: the real scene runs once, at its own scale, when --scales has it
    for d in present:
        d_scales = [REAL_SCALE] if d == "RGBDD_Test_Realscene" and REAL_SCALE in scales else \
            ([] if d == "RGBDD_Test_Realscene" else scales)
        if not d_scales:
            print(f"gdsr: skipping {d}: its real input is upsampled x{REAL_SCALE} only; add {REAL_SCALE} to --scales",
                  file=sys.stderr)
        if not images[d]:
            print(f"gdsr: no images of {d} match --scenes {getattr(args, 'scenes', None)}", file=sys.stderr)
        jobs += [(img, s) for img in images[d] for s in d_scales]
    if not jobs:
        raise UsageError("gdsr: nothing to run (check --sets, --scales and --scenes)")
    models: dict = {}
    results = []
    bar = tqdm(total=len(jobs) * len(noises) * len(methods), desc="bench gdsr", unit="run")
    for img, s in jobs:
        for noise in noises:
            sample = degrade(img, s, noise)
            gt = sample["gt"]
            for m in methods:
                row = {"track": "gdsr", "dataset": img.dataset, "image": img.name, "scene": img.scene,
                       "heldout": img.heldout, "scale": s, "noise": noise, "method": m,
                       "units": "grey levels" if img.dataset in GREY_SETS else "cm"}
                t0 = time.perf_counter()
                if m == "bicubic":
                    pred = bicubic(sample["lr"], tuple(gt.shape[-2:]))
                else:
                    key = (m, sample["factor"])
                    if key not in models:
                        models[key] = make_model(m, sample["factor"], config, device,
                                                 getattr(args, "pretrained", None))
                    pred = None if models[key] is None else _run_model(models[key], sample, device)
                if pred is None:
                    row.update(rmse=None, available=False, seconds=None,
                               note=f"no shipped {m} model for x{sample['factor']}")
                else:
                    row.update(rmse=rmse(pred, gt, img.dataset), available=True,
                               seconds=time.perf_counter() - t0)
                results.append(row)
                bar.update(1)
    bar.close()
    summary = summarise_gdsr(results)
    print_table(summary, ["dataset", "subset", "n", "scale", "noise", "method", "rmse", "units", "seconds"],
                "track gdsr: mean RMSE over images (grey levels for Middlebury/Lu, cm for NYU/RGB-D-D); "
                "rmse empty = no such model")
    if getattr(args, "per_scene", False):
        print_table(results, ["image", "scene", "heldout", "scale", "noise", "method", "rmse", "seconds"], "per image")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        meta = metadata(device)
        meta.update(track="gdsr", sets=present, scales=scales, noise=noises, methods=methods, data=str(root),
                    scenes=getattr(args, "scenes", None), max_images=getattr(args, "max_images", None),
                    noise_seed=NOISE_SEED, config_overrides=config or {},
                    full_config={"degradation": "bicubic", **(config or {})}, real_scale=REAL_SCALE)
        Path(args.json).write_text(json.dumps({"metadata": meta, "summary": summary, "results": results}, indent=1))
        print(f"json: {args.json}")
    return 0


def summarise_gdsr(results: list[dict]) -> list[dict]:
    """Mean RMSE per set, scale, noise and method over all images, and for Middlebury over the held-out ones."""
    out = []
    keys = list(dict.fromkeys((r["dataset"], r["scale"], r["noise"], r["method"]) for r in results))
    for d, s, n, m in keys:
        rows = [r for r in results if (r["dataset"], r["scale"], r["noise"], r["method"]) == (d, s, n, m)]
        for subset in ("all", "heldout") if d == "Middlebury" else ("all",):
            sel = [r for r in rows if subset == "all" or r["heldout"]]
            if not sel:
                continue
            ok = [r for r in sel if r["rmse"] is not None]
            agg = {"dataset": d, "subset": subset, "n": len(sel), "scale": s, "noise": n, "method": m,
                   "units": sel[0]["units"], "rmse": float(np.mean([r["rmse"] for r in ok])) if ok else None,
                   "available": bool(ok)}
            if ok:
                agg["seconds"] = float(np.mean([r["seconds"] for r in ok]))
            out.append(agg)
    out.sort(key=lambda a: (list(SETS).index(a["dataset"]), a["subset"] != "all", a["noise"], a["scale"],
                            list(METHODS).index(a["method"]) if a["method"] in METHODS else 99))
    return out
