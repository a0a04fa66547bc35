"""Training scenes at a finer pixel pitch: a scene upscaled so that its surfaces are as smooth per pixel as a
full-size capture's.

The project trains on the third-size Middlebury 2006 maps, but the ``upsample-b`` set is full size: at a given
factor its low-resolution input holds a third of the scene detail per pixel, and a network that learned how much to
smooth on third-size surfaces smooths full-size ones too little. :func:`upscale_scene` makes a training scene of
the pitch of a larger capture from the same data (no new scene): the colour bicubically, the depth bicubically on
surfaces and, where the 3×3 neighbourhood spans a depth edge, snapped to the nearest of its nine values (a sharp
edge with a smooth contour instead of a ramp that no sensor measures), then rounded to whole grey levels as the
8-bit ground truths are. Holes stay holes.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

__all__ = ["upscale_scene"]

EDGE_SPAN = 8.0  # grey levels over a 3×3 neighbourhood beyond which it is a depth edge, not a slanted surface


def _filled(gt: torch.Tensor, known: torch.Tensor) -> torch.Tensor:
    """``gt`` (1,1,H,W) with its unknown pixels set to the mean of their known 3×3 neighbours, grown inwards."""
    value, weight = gt * known, known.clone()
    while bool((weight == 0).any()):
        grown_value = F.avg_pool2d(value, 3, 1, 1, count_include_pad=False)
        grown_weight = F.avg_pool2d(weight, 3, 1, 1, count_include_pad=False)
        newly = (weight == 0) & (grown_weight > 0)
        if not bool(newly.any()):
            break
        value = torch.where(newly, grown_value / grown_weight.clamp_min(1e-12), value)
        weight = torch.where(newly, torch.ones_like(weight), weight)
    return value


def upscale_scene(scene: dict, factor: int) -> dict:
    """``scene`` (``rgb`` (3,H,W) in [0, 1], ``gt`` and ``mask`` (1,H,W), ``name``) at ``factor`` times its size.

    Examples:
        >>> gt = torch.full((1, 8, 8), 50.0); gt[:, :, 4:] = 150.0
        >>> big = upscale_scene({"rgb": torch.rand(3, 8, 8), "gt": gt, "mask": torch.ones(1, 8, 8), "name": "s"}, 2)
        >>> big["gt"].shape, sorted(big["gt"].unique().tolist())  # a sharp edge, no value in between
        (torch.Size([1, 16, 16]), [50.0, 150.0])
    """
    if factor == 1:
        return scene
    known = (scene["mask"][None] > 0).float()
    depth = _filled(scene["gt"][None].float(), known)
    size = (depth.shape[-2] * factor, depth.shape[-1] * factor)
    smooth = F.interpolate(depth, size=size, mode="bicubic", align_corners=False)
    neighbours = F.unfold(F.pad(depth, (1, 1, 1, 1), mode="replicate"), 3).view(1, 9, *depth.shape[-2:])
    neighbours = F.interpolate(neighbours, size=size, mode="nearest")
    lo, hi = neighbours.amin(1, keepdim=True), neighbours.amax(1, keepdim=True)
    smooth = torch.minimum(torch.maximum(smooth, lo), hi)  # no bicubic overshoot beside an edge
    nearest = neighbours.gather(1, (neighbours - smooth).abs().argmin(1, keepdim=True))
    edge = (hi - lo) > EDGE_SPAN
    gt = torch.where(edge, nearest, smooth).round()
    mask = F.interpolate(known, size=size, mode="nearest")
    rgb = F.interpolate(scene["rgb"][None].float(), size=size, mode="bicubic", align_corners=False).clamp(0, 1)
    return {"rgb": rgb[0], "gt": (gt * mask)[0], "mask": mask[0], "name": f"{scene['name']}@x{factor}"}
