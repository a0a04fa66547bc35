"""``torch-depth-sr restore``: files or folders of depth (+ colour) in, same names, units and dtype out."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset
from tqdm import tqdm

from .datasets.io import read_depth, read_rgb, write_npy, write_pfm, write_png_depth
from .errors import DepthSRError

DEPTH_EXTS = (".png", ".pfm", ".npy", ".pgm", ".tif", ".tiff")
RGB_EXTS = (".png", ".jpg", ".jpeg", ".ppm", ".bmp", ".tif", ".tiff")


class DepthFilePairs(Dataset):
    """Pairs (depth file, colour file or None), read in DataLoader workers."""

    def __init__(self, depth_paths: list[Path], rgb_paths: list[Path | None]):
        self.depth_paths, self.rgb_paths = depth_paths, rgb_paths

    def __len__(self) -> int:
        return len(self.depth_paths)

    def __getitem__(self, i: int) -> dict:
        d = read_depth(self.depth_paths[i])
        rgb = None if self.rgb_paths[i] is None else read_rgb(self.rgb_paths[i])
        return {"index": i, "depth": d, "rgb": rgb}


def _pair_folders(depth_dir: Path, rgb_dir: Path | None) -> tuple[list[Path], list[Path | None]]:
    depths = sorted(p for p in depth_dir.iterdir() if p.suffix.lower() in DEPTH_EXTS)
    if not depths:
        raise DepthSRError(f"no depth files ({', '.join(DEPTH_EXTS)}) in folder {depth_dir}")
    if rgb_dir is None:
        return depths, [None] * len(depths)
    rgbs = {p.stem: p for p in rgb_dir.iterdir() if p.suffix.lower() in RGB_EXTS}
    missing = [p.name for p in depths if p.stem not in rgbs]
    if not missing:
        return depths, [rgbs[p.stem] for p in depths]
    ordered = sorted(rgbs.values())
    if len(ordered) != len(depths):
        raise DepthSRError(f"colour folder {rgb_dir} has no file with the same name as {missing[:3]}... and holds "
                           f"{len(ordered)} colour files for {len(depths)} depth files; pair them by name or by "
                           "sorted order with equal counts.")
    return depths, ordered


def write_like(path: Path, src: Path, depth: np.ndarray) -> None:
    """Write ``depth`` to ``path`` in the format and dtype that ``src`` had."""
    path.parent.mkdir(parents=True, exist_ok=True)
    ext = src.suffix.lower()
    if ext == ".pfm":
        write_pfm(path, depth.astype(np.float32))
    elif ext == ".npy":
        write_npy(path, depth)
    else:
        if path.suffix.lower() not in (".png", ".tif", ".tiff"):
            path = path.with_suffix(".png")
        write_png_depth(path, depth, bits=8 if depth.dtype == np.uint8 else 16)


def _to_model_input(depth: np.ndarray) -> np.ndarray:
    if depth.dtype.kind == "f":
        return np.where(np.isfinite(depth), depth, np.nan)  # PFM marks unknown with inf
    return depth


def restore_paths(args) -> int:
    from .model import DepthRestorer

    model = DepthRestorer.from_pretrained(args.pretrained) if args.pretrained else DepthRestorer()
    model = model.to(args.device)
    depth_in, out = Path(args.depth), Path(args.output)
    rgb_in = Path(args.rgb) if args.rgb else None
    if depth_in.is_dir():
        if rgb_in is not None and not rgb_in.is_dir():
            raise DepthSRError(f"depth {depth_in} is a folder, so rgb must be a folder too; got {rgb_in}")
        depths, rgbs = _pair_folders(depth_in, rgb_in)
        targets = [out / p.name for p in depths]
    else:
        depths, rgbs, targets = [depth_in], [rgb_in], [out]
    loader = DataLoader(DepthFilePairs(depths, rgbs), batch_size=None, num_workers=args.workers)
    for item in tqdm(loader, total=len(depths), desc="restore", unit="frame", disable=len(depths) < 2):
        i = item["index"]
        d = item["depth"]
        d = d.numpy() if isinstance(d, torch.Tensor) else d
        rgb = item["rgb"]
        rgb_t = None if rgb is None else torch.as_tensor(np.asarray(rgb)).permute(2, 0, 1)[None].to(args.device)
        with torch.no_grad():
            res = model(_to_model_input(d), rgb_t, scale_factor=args.scale_factor, return_details=True)
        write_like(targets[i], depths[i], np.asarray(res.depth))
        if getattr(args, "confidence", None):
            conf_dir = Path(args.confidence)
            conf_path = conf_dir / (depths[i].stem + "_confidence.png") if len(depths) > 1 or conf_dir.is_dir() \
                else conf_dir
            conf_map = res.confidence.cpu().numpy() if isinstance(res.confidence, torch.Tensor) else res.confidence
            conf = (np.asarray(conf_map).reshape(conf_map.shape[-2:]) * 255).round().astype(np.uint8)
            conf_path.parent.mkdir(parents=True, exist_ok=True)
            write_png_depth(conf_path, conf, bits=8)
        if len(depths) == 1:
            print(f"wrote {targets[i]}")
    return 0
