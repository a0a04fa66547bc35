"""The "Noisy Middlebury" guided depth-upsampling sets (Park et al. 2011; Ferstl et al. 2013).

Layouts (``shared/data/README.md`` §2, §2b):

* ``park2011``: ``noisy_middlebury_park2011/<scene>/<scene>_{color,big,depth_k_n}.png``
  (i.i.d. noise; scenes art, book, dolls, laundry, moebius, reindeer) — track ``upsample-b``.
* ``ferstl2013``: ``noisy_middlebury_ferstl2013/<scene>/{color,gt,depth_k_n}.png``
  (depth-dependent noise; art, books, moebius) — track ``upsample-a``.

``k = 1..4`` is the downsampling exponent: factor ``2**k``. Samples: ``depth`` (1,h,w) the noisy
LOW-resolution input (0 = missing; there are none), ``rgb`` (3,H,W) and ``gt`` (1,H,W) at full
resolution (hole-filled 8-bit disparity at full size, so ``scale`` = 1 grey level per pixel),
``mask`` (all ones where gt > 0), ``factor`` (int), ``name``, ``dataset``, ``path``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Dict, Optional, Sequence, Union

from torch.utils.data import Dataset

from torch_depth_sr.datasets.io import read_png_depth, read_rgb, sample_from_arrays
from torch_depth_sr.errors import DepthSRError

VARIANTS = {"park2011": "noisy_middlebury_park2011", "ferstl2013": "noisy_middlebury_ferstl2013"}
FACTORS = {2: 1, 4: 2, 8: 3, 16: 4}


def noisy_scene_files(scene_dir: Union[str, Path], variant: str) -> Dict[str, Path]:
    """Paths of one scene: ``{'color', 'gt', 'depth_2', 'depth_4', 'depth_8', 'depth_16'}``."""
    d = Path(scene_dir)
    if variant == "park2011":
        s = d.name
        files = {"color": d / f"{s}_color.png", "gt": d / f"{s}_big.png"}
        files.update({f"depth_{f}": d / f"{s}_depth_{k}_n.png" for f, k in FACTORS.items()})
    elif variant == "ferstl2013":
        files = {"color": d / "color.png", "gt": d / "gt.png"}
        files.update({f"depth_{f}": d / f"depth_{k}_n.png" for f, k in FACTORS.items()})
    else:
        raise DepthSRError(f"variant={variant!r} is not allowed; use 'park2011' or 'ferstl2013'")
    return files


def identify_noisy_scene(scene_dir: Union[str, Path]) -> Optional[str]:
    """Return ``'park2011'`` / ``'ferstl2013'`` if ``scene_dir`` holds that layout, else None."""
    d = Path(scene_dir)
    for v in ("park2011", "ferstl2013"):
        f = noisy_scene_files(d, v)
        if f["color"].is_file() and f["gt"].is_file():
            return v
    return None


def load_noisy_scene(scene_dir: Union[str, Path], variant: str, factor: int) -> dict:
    """Load one scene at one upsampling factor (2, 4, 8 or 16) as a sample dict."""
    if factor not in FACTORS:
        raise DepthSRError(f"factor={factor} is not allowed; use one of {sorted(FACTORS)}")
    d = Path(scene_dir)
    files = noisy_scene_files(d, variant)
    gt = read_png_depth(files["gt"])
    rgb = read_rgb(files["color"])
    lr = read_png_depth(files[f"depth_{factor}"])
    return sample_from_arrays(
        lr, rgb, gt, 1.0, d.name, VARIANTS[variant], factor=int(factor), path=str(d)
    )


class NoisyMiddleburyUpsampling(Dataset):
    """Noisy Middlebury upsampling scenes at one factor.

    Args:
        root: the data root (holding ``noisy_middlebury_<variant>/``) or the variant folder itself.
        variant: ``'park2011'`` (track upsample-b) or ``'ferstl2013'`` (track upsample-a).
        factor: 2, 4, 8 or 16.
        scenes: optional subset of scene names (lower case as stored, e.g. ``'art'``).
    """

    def __init__(self, root: Union[str, Path], variant: str = "park2011", factor: int = 4,
                 scenes: Optional[Sequence[str]] = None) -> None:
        if variant not in VARIANTS:
            raise DepthSRError(f"variant={variant!r} is not allowed; use 'park2011' or 'ferstl2013'")
        if factor not in FACTORS:
            raise DepthSRError(f"factor={factor} is not allowed; use one of {sorted(FACTORS)}")
        root = Path(root)
        folder = root if root.name == VARIANTS[variant] or not (root / VARIANTS[variant]).is_dir() else root / VARIANTS[variant]
        self.variant, self.factor = variant, int(factor)
        keep = None if scenes is None else {s.lower() for s in scenes}
        self.scene_dirs = []
        if folder.is_dir():
            for d in sorted(p for p in folder.iterdir() if p.is_dir()):
                if (keep is None or d.name.lower() in keep) and identify_noisy_scene(d) == variant:
                    self.scene_dirs.append(d)
        if not self.scene_dirs:
            raise DepthSRError(
                f"no {variant} scenes under '{root}'; expected {VARIANTS[variant]}/<scene>/ with the files "
                f"{sorted(p.name for p in noisy_scene_files(Path('<scene>'), variant).values())}"
            )

    def __len__(self) -> int:
        return len(self.scene_dirs)

    def __getitem__(self, i: int) -> dict:
        return load_noisy_scene(self.scene_dirs[i], self.variant, self.factor)


__all__ = [
    "FACTORS",
    "NoisyMiddleburyUpsampling",
    "VARIANTS",
    "identify_noisy_scene",
    "load_noisy_scene",
    "noisy_scene_files",
]
