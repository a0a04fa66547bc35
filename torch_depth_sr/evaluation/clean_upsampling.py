"""Guided upsampling against bicubic interpolation on the guided-SR test images (issue 12, "do no harm").

``python -m torch_depth_sr.evaluation.clean_upsampling [--sets Middlebury Lu] [--scale 4] [--noise 0]
[--images 03 09 ...] [--trials JSON ...]`` prints, per image, the RMSE of bicubic interpolation and of the model
for each trial (a JSON dict of ``RestorerConfig`` overrides; default: the defaults), then the means (all
images, and the images that are not Middlebury 2006 fitting scenes) and on how many images each trial is
worse than bicubic.

Protocol (``../shared/docs/benchmark.md``, track ``gdsr``, grey-level sets only): crop to a multiple of the
scale, antialiased bicubic downsampling (torch's, which reproduces Pillow's), optional Gaussian noise of
``noise`` on a 0–255 scale of the image's range, RMSE over all pixels after clipping to [0, 255]. Input
values at or below 0 (bicubic overshoot, noise) are missing for the model, as in ``bench``. This is a
check of the frozen model, not the ``gdsr`` benchmark track of issue 14 (no NYU/RGB-D-D, no deep networks).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from .._data_root import data_root
from ..model import DepthRestorer

__all__ = ["FITTING", "images", "degrade", "rmse_grey", "main"]

# Middlebury files of the guided-SR set that are 2006 scenes (the fitting split; data README, section 4)
FITTING = {"03", "04", "05", "09", "10", "11", "12", "19", "20", "28", "29"}


def images(root: Path, dataset: str, only: list[str] | None = None):
    """Yield ``(name, depth float32 (H,W), rgb uint8 (H,W,3))`` of one grey-level set, sorted by name."""
    import cv2

    folder = root / "guided_dsr_testsets_dctnet" / dataset
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder} not found; set TORCH_DEPTH_SR_DATA to the shared data folder")
    for p in sorted((folder / "Depth").glob("*_output_depth.png")):
        index = p.name.split("_")[1]
        if only and index not in only:
            continue
        depth = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        depth = (depth[..., 0] if depth.ndim == 3 else depth).astype(np.float32)
        colour = sorted((folder / "RGB").glob(f"{p.name.split('_')[0]}_{index}_*"))  # Lu's files say "ouput"
        if len(colour) != 1:
            raise FileNotFoundError(f"expected one colour image for {p.name} in {folder / 'RGB'}; found {colour}")
        rgb = cv2.imread(str(colour[0]))[..., ::-1]
        yield f"{dataset}_{index}", depth, np.ascontiguousarray(rgb)


def degrade(gt: torch.Tensor, s: int, noise: float, seed: int = 0):
    """Crop ``gt (1,1,H,W)`` to a multiple of ``s``; return it, the low-resolution input and bicubic back up."""
    h, w = gt.shape[-2] // s * s, gt.shape[-1] // s * s
    gt = gt[..., :h, :w]
    lr = F.interpolate(gt, size=(h // s, w // s), mode="bicubic", antialias=True, align_corners=False)
    if noise > 0:
        g = torch.Generator().manual_seed(seed)
        lr = lr + noise * float(gt.max() - gt.min()) / 255 * torch.randn(lr.shape, generator=g)
    return gt, lr, F.interpolate(lr, scale_factor=s, mode="bicubic", align_corners=False)


def rmse_grey(p: torch.Tensor, gt: torch.Tensor) -> float:
    return float((p.clamp(0, 255) - gt.clamp(0, 255)).square().mean().sqrt())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sets", nargs="*", default=["Middlebury", "Lu"])
    ap.add_argument("--scale", type=int, default=4)
    ap.add_argument("--noise", type=float, default=0.0)
    ap.add_argument("--images", nargs="*", default=None, help="file indices, e.g. 03 09 (default: all)")
    ap.add_argument("--trials", nargs="*", default=None, help="JSON dicts of RestorerConfig overrides")
    ap.add_argument("--data", default=None)
    args = ap.parse_args(argv)
    trials = [json.loads(t) for t in args.trials] if args.trials else [{}]
    labels = ["bicubic"] + [json.dumps(t) for t in trials]
    models = [DepthRestorer(**t) for t in trials]
    root = Path(args.data) if args.data else data_root()
    rows = []
    for dataset in args.sets:
        for name, depth, rgb in tqdm(list(images(root, dataset, args.images)), desc=dataset, unit="image"):
            gt, lr, bicubic = degrade(torch.from_numpy(depth)[None, None], args.scale, args.noise)
            h, w = gt.shape[-2:]
            guide = torch.from_numpy(rgb[:h, :w].copy()).permute(2, 0, 1)[None].float() / 255
            with torch.no_grad():
                # the bicubic overshoot can make dark-edge inputs negative: missing for the model (as in `bench`)
                lr_model = torch.where(lr > 0, lr, torch.full_like(lr, float("nan")))
                errs = [rmse_grey(bicubic, gt)] + [rmse_grey(m(lr_model, guide), gt) for m in models]
            held_out = not (dataset == "Middlebury" and name.split("_")[1] in FITTING)
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
