"""The initial estimate x⁰ of guided upsampling, on the output grid, and the do-no-harm hold of the output to it.

Joint bilateral upsampling (Kopf et al. 2007) of the low-resolution estimate, first order (each tap extrapolated
along its limited slope, :func:`~torch_depth_sr.guided_filters.joint_bilateral_upsample`), held in a band around
bicubic interpolation. The band is what keeps the colour image from doing harm: away from depth edges a colour
edge must not move the depth (on clean input the unbounded filter was worse than bicubic interpolation, issue 12),
while at a depth edge bicubic interpolation blurs the step over ``s`` pixels and the colour image is what puts it
back in place. So the band is ``init_band`` noise σ everywhere plus ``init_edge_band`` times the local depth-edge
evidence :func:`plane_residual` of the low-resolution input. Where the colour image puts an edge somewhere the data
do not (printed patterns on cloth, shadows), the filtered estimate, degraded by ``K``, no longer reproduces the
input: there the edge band is refused (``init_consistency``).

After the layers, :func:`hold_to_initial` keeps the output within a band of x⁰ rebuilt with the *white* noise level
(:func:`~torch_depth_sr.noise.white_noise_sigma`): 0 on a clean map, whose fine texture the layers would otherwise
smooth as noise.

On the eleven Middlebury 2006 images of the guided-SR test set, ×4 (``python -m
torch_depth_sr.evaluation.clean_upsampling --sets Middlebury --images 03 04 05 09 10 11 12 19 20 28 29``), the
choices each moved the mean RMSE: see ``docs/results/`` (clean upsampling) for the figures.

The filters that do not depend on the noise level (bicubic interpolation, the JBU, the edge evidence) run once per
forward (:func:`upsampling_reference`); x⁰ and the hold bound them with their own noise levels.
"""
from __future__ import annotations

from typing import Optional

import torch
import torch.nn.functional as F

from typing import NamedTuple

from .band import clamp_between
from .config import OutputHold, UpsamplingConfig
from .guided_filters import joint_bilateral_upsample
from .operators import Degradation, degradation_operator
from .window_max import max_filter

__all__ = ["UpsamplingReference", "bounded_upsample", "hold_to_initial", "plane_residual", "upsample_initial",
           "upsampling_reference"]


def plane_residual(depth: torch.Tensor, size: int = 3) -> torch.Tensor:
    """The largest deviation of each ``size × size`` window of ``depth (B,1,h,w)`` from its least-squares
    plane, per pixel (a border pixel takes its nearest whole window's): 0 on planes, a third of the step beside a
    depth edge, the noise level (a few σ) on noisy flat ground. Curved surfaces give a little (their second
    differences).

    Examples:
        >>> yy, xx = torch.meshgrid(torch.arange(6.0), torch.arange(7.0), indexing="ij")
        >>> float(plane_residual((2 * xx - yy + 9)[None, None]).abs().max()) < 1e-5
        True
        >>> step = torch.zeros(1, 1, 6, 7); step[..., 4:] = 9.0
        >>> plane_residual(step)[0, 0, 3].tolist()
        [0.0, 0.0, 0.0, 3.0, 3.0, 0.0, 0.0]
    """
    r = size // 2
    h, w = depth.shape[-2:]
    if h < size or w < size:
        return torch.zeros_like(depth)
    windows = F.unfold(depth, size)  # (B, size², (h-2r)·(w-2r)): whole windows only
    offsets = torch.arange(size, dtype=depth.dtype, device=depth.device) - r
    oy = offsets.repeat_interleave(size).view(1, -1, 1)
    ox = offsets.repeat(size).view(1, -1, 1)
    norm = (ox**2).sum()
    mean = windows.mean(1, keepdim=True)
    slope_x = (windows * ox).sum(1, keepdim=True) / norm
    slope_y = (windows * oy).sum(1, keepdim=True) / norm
    residual = (windows - mean - slope_x * ox - slope_y * oy).abs().amax(1)
    residual = residual.view(depth.shape[0], 1, h - 2 * r, w - 2 * r)
    return F.pad(residual, (r, r, r, r), mode="replicate")  # border pixels: their nearest whole window


class UpsamplingReference(NamedTuple):
    """What x⁰ and the output hold are built from, computed once per forward: the filled low-resolution estimate,
    its bicubic interpolation and joint bilateral upsampling (None when x⁰ is bicubic) on the fine grid, and the 3×3
    maximum of its :func:`plane_residual` on the low-resolution grid (the depth-edge evidence)."""

    lowres: torch.Tensor  # (B,1,h,w)
    bicubic: torch.Tensor  # (B,1,H,W)
    jbu: Optional[torch.Tensor]  # (B,1,H,W)
    evidence: torch.Tensor  # (B,1,h,w)


def upsampling_reference(x0_lr: torch.Tensor, observed: torch.Tensor, guide: Optional[torch.Tensor], factor: int,
                         c: UpsamplingConfig) -> UpsamplingReference:
    """The :class:`UpsamplingReference` of ``x0_lr (B,1,h,w)`` (holes already filled) for a grid ``factor`` times
    finer; the JBU (``c.init == "jbu"`` and a guide) by ``c.jbu``, every low-resolution pixel a tap (``observed``
gives the mask's shape and dtype)."""
    bicubic = F.interpolate(x0_lr, scale_factor=factor, mode="bicubic", align_corners=False)
    jbu = None
    if c.init == "jbu" and guide is not None:
        jbu = joint_bilateral_upsample(x0_lr, guide, factor, mask=torch.ones_like(observed), radius=c.jbu.radius,
                                       sigma_space=c.jbu.sigma_space, sigma_color=c.jbu.sigma_color,
                                       first_order=c.jbu.first_order)
    evidence = max_filter(plane_residual(x0_lr), 3)
    return UpsamplingReference(x0_lr, bicubic, jbu, evidence)


def bounded_upsample(ref: UpsamplingReference, K: Degradation, c: UpsamplingConfig,
                     noise: Optional[torch.Tensor] = None) -> torch.Tensor:
    """x⁰ on the fine grid: bicubic interpolation without a JBU; else the JBU held within ``c.init_band · noise +
    c.init_edge_band · E`` of bicubic interpolation, ``noise (B,)`` the noise σ in the units of ``ref.lowres`` and
    ``E`` the edge evidence on the fine grid, refused on the low-resolution pixels where ``K(jbu)`` is further from
    the input than ``K(bicubic)`` is by more than ``c.init_consistency · noise``. Both bands 0 (or no ``noise`` with
    ``init_edge_band`` 0): the unbounded JBU."""
    if ref.jbu is None:  # x⁰ is bicubic interpolation (by the settings, or without a colour image)
        return ref.bicubic
    bicubic, jbu = ref.bicubic, ref.jbu
    if (noise is None or c.init_band <= 0) and c.init_edge_band <= 0:  # no band: the unbounded filter
        return jbu
    sigma = None if noise is None else noise.to(jbu).view(-1, 1, 1, 1)
    band = c.init_band * (torch.zeros_like(jbu[:, :, :1, :1]) if sigma is None else sigma)
    band = band + c.init_edge_band * _edge_evidence(ref, K, c.init_consistency, sigma)
    return bicubic + clamp_between(jbu - bicubic, -band, band)


def upsample_initial(x0_lr: torch.Tensor, observed: torch.Tensor, guide: Optional[torch.Tensor], factor: int,
                     c: UpsamplingConfig, noise: Optional[torch.Tensor] = None, degradation: Optional[Degradation] = None,
                     degradation_kind: str = "area") -> torch.Tensor:
    """x⁰ on the grid ``factor`` times finer than ``x0_lr (B,1,h,w)``: :func:`bounded_upsample` of its
    :func:`upsampling_reference` (``K``: ``degradation``, else a ``degradation_kind`` K by ``factor``).
    """
    K = degradation if degradation is not None else degradation_operator(degradation_kind, factor)
    return bounded_upsample(upsampling_reference(x0_lr, observed, guide, factor, c), K, c, noise)


def _edge_evidence(ref: UpsamplingReference, K: Degradation, consistency: float,
                   sigma: Optional[torch.Tensor]) -> torch.Tensor:
    """The edge evidence on the fine grid, 0 where ``K(jbu)`` leaves the input by more than ``K(bicubic)`` does plus
    ``consistency · sigma`` (no check without ``sigma`` or with ``consistency`` 0)."""
    evidence = ref.evidence
    if sigma is not None and consistency > 0:
        moved = (K(ref.jbu) - ref.lowres).abs() > (K(ref.bicubic) - ref.lowres).abs() + consistency * sigma
        evidence = torch.where(moved, torch.zeros_like(evidence), evidence)
    return F.interpolate(evidence, scale_factor=K.scale, mode="nearest")


def hold_to_initial(x: torch.Tensor, ref: UpsamplingReference, K: Degradation, c: UpsamplingConfig,
                    hold: OutputHold, noise: torch.Tensor, white: torch.Tensor,
                    separate_evidence: bool = False) -> torch.Tensor:
    """Do no harm on upsampling: the restored ``x (B,1,H,W)`` held within ``hold.band · white + hold.edge ·
    max(E − hold.edge_threshold · noise, 0)`` of x⁰ rebuilt with the noise ``white`` (:func:`bounded_upsample`;
    ``E`` the depth-edge evidence on the fine grid).

    ``noise (B,)`` is the model's noise level, ``white (B,)`` the white part of it
    (:func:`~torch_depth_sr.noise.white_noise_sigma`), both in the units of ``ref.lowres``. On a clean map whose fine
    texture (Middlebury Cloth1's ripples) has second differences of the noise level, ``white`` is 0: away from
    depth edges the output is x⁰, which is bicubic interpolation there, instead of the regularised surface that took
    the texture for noise (issue 12). Under noise the band is 3σ wide and hardly binds.

    ``separate_evidence``: compute the edge evidence again here instead of reading ``ref``'s (same values; see
    :class:`~torch_depth_sr.post_steps.OutputHoldStep`).
    """
    rebuilt = bounded_upsample(ref, K, c, noise=white)
    own = max_filter(plane_residual(ref.lowres), 3) if separate_evidence else ref.evidence
    evidence = F.interpolate(own, scale_factor=K.scale, mode="nearest")
    n4, w4 = noise.to(x).view(-1, 1, 1, 1), white.to(x).view(-1, 1, 1, 1)
    band = hold.band * w4 + hold.edge * (evidence - hold.edge_threshold * n4).clamp_min(0)
    return clamp_between(x, rebuilt - band, rebuilt + band)
