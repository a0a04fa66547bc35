"""Guided upsampling against bicubic interpolation on the guided-SR test images (issue 12, "do no harm").

``python -m torch_depth_sr.evaluation.clean_upsampling [--sets Middlebury Lu] [--scale 4] [--noise 0]
[--images 03 09 ...] [--trials JSON ...] [--noise-sigma S]`` prints, per image, the RMSE of bicubic interpolation
and of the model for each trial (a JSON dict of ``RestorerConfig`` overrides, as
:func:`~torch_depth_sr.config.apply_overrides` takes them; default: the defaults), then the means (all images, and
the images that are not Middlebury 2006 fitting scenes) and on how many images each trial is worse than bicubic.

Protocol (``../shared/docs/benchmark.md``, track ``gdsr``, grey-level sets only), the same code as the track
(:mod:`torch_depth_sr.evaluation.gdsr`, readers in :mod:`torch_depth_sr.datasets.gdsr`): crop to a multiple of the
scale, Pillow's antialiased bicubic downsampling, optional Gaussian noise of ``noise`` on a 0–255 scale of the
image's range (seeded per image), bicubic = Pillow's bicubic upsampling, RMSE over all pixels after clipping to
[0, 255]. Input values at or below 0 (bicubic overshoot, noise) are missing for the model, as in ``bench``. This
is a check of the frozen model (default ``RestorerConfig`` plus the trials); ``bench --track gdsr`` is the
benchmark.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Iterator, Optional, Sequence

import numpy as np
import torch
from tqdm import tqdm

from .._data_root import data_root
from ..datasets.gdsr import FITTING, gdsr_images
from ..config import RestorerConfig, apply_overrides
from ..model import DepthRestorer
from .gdsr import add_noise, bicubic as _bicubic, crop_to_multiple, degrade as _degrade_image, resize_pillow, rmse

__all__ = ["FITTING", "images", "degrade", "rmse_grey", "main"]


def images(root: Path, dataset: str, only: list[str] | None = None) -> Iterator[tuple[str, np.ndarray, np.ndarray]]:
    """Yield ``(name, depth float32 (H,W), rgb uint8 (H,W,3))`` of one grey-level set, sorted by name
    (:func:`torch_depth_sr.datasets.gdsr.gdsr_images`)."""
    for img in gdsr_images(root, dataset, only):
        yield img.name, img.depth, img.rgb


def degrade(gt: torch.Tensor, s: int, noise: float, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Crop ``gt (1,1,H,W)`` to a multiple of ``s``; return it, the low-resolution input and bicubic back up
    (the ``gdsr`` protocol's resampling; noise drawn from a generator named by ``seed``)."""
    gt = crop_to_multiple(gt, s)
    h, w = gt.shape[-2:]
    lr = add_noise(resize_pillow(gt, (h // s, w // s)), noise, float(gt.max() - gt.min()), f"clean_upsampling/{seed}")
    return gt, lr, _bicubic(lr, (h, w))


def rmse_grey(p: torch.Tensor, gt: torch.Tensor) -> float:
    return rmse(p, gt, "Middlebury")


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sets", nargs="*", default=["Middlebury", "Lu"])
    ap.add_argument("--scale", type=int, default=4)
    ap.add_argument("--noise", type=float, default=0.0)
    ap.add_argument("--images", nargs="*", default=None, help="file indices, e.g. 03 09 (default: all)")
    ap.add_argument("--trials", nargs="*", default=None,
                    help='JSON dicts of RestorerConfig overrides (docs/config.md), e.g. \'{"upsample_hold": null}\', '
                         '\'{"upsampling.init_band": 2.0}\' or the version-1 \'{"upsample_init_band": 2.0}\'')
    ap.add_argument("--noise-sigma", type=float, default=None,
                    help="pass this noise_sigma (grey levels) to the model instead of letting it estimate σ "
                         "(0: the caller knows the input is noise-free)")
    ap.add_argument("--data", default=None)
    args = ap.parse_args(argv)
    trials = [json.loads(t) for t in args.trials] if args.trials else [{}]
    labels = ["bicubic"] + [json.dumps(t) for t in trials]
    models = [DepthRestorer(apply_overrides(RestorerConfig(), t)) for t in trials]
    root = Path(args.data) if args.data else data_root()
    rows = []
    for dataset in args.sets:
        for img in tqdm(list(gdsr_images(root, dataset, args.images)), desc=dataset, unit="image"):
            sample = _degrade_image(img, args.scale, args.noise)
            gt, lr, guide = sample["gt"], sample["lr"], sample["rgb"]
            bicubic = _bicubic(lr, tuple(gt.shape[-2:]))
            name = img.name
            with torch.no_grad():
                # the bicubic overshoot can make dark-edge inputs negative: missing for the model (as in `bench`)
                lr_model = torch.where(lr > 0, lr, torch.full_like(lr, float("nan")))
                errs = [rmse_grey(bicubic, gt)] + [rmse_grey(m(lr_model, guide, noise_sigma=args.noise_sigma), gt)
                                                     for m in models]
            held_out = img.heldout
            rows.append((name, held_out, errs))
            print(f"{name:16s} " + "  ".join(f"{e:7.3f}" for e in errs), flush=True)
    print(f"\nx{args.scale}, noise {args.noise}; columns: " + " | ".join(labels))
    for what, keep in (("all", lambda r: True), ("held out", lambda r: r[1])):
        sel = [r for r in rows if keep(r)]
        if sel:
            means = np.mean([r[2] for r in sel], axis=0)
            print(f"mean, {what} ({len(sel)}): " + "  ".join(f"{m:.3f}" for m in means))
    for j, label in enumerate(labels[1:], start=1):
        worse = [r[0] for r in rows if r[2][j] > r[2][0]]
        print(f"{label}: worse than bicubic on {len(worse)} of {len(rows)} {worse}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
