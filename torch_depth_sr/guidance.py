r"""A small convolutional guidance network that turns the layers' scalar weights into per-pixel maps.

Issue 14 item 2 ("more capacity, same structure"). The trainable model learns five positive scalars per layer;
with ``RestorerConfig(guidance_net=True)`` a :class:`GuidanceNet`, shared by all layers, predicts from the colour
image and the current estimate per-pixel multipliers of the layer's thresholds:

.. math::
    z &= \operatorname{soft}\big(Dx,\ m^{\mathrm{tv}}_k \odot \lambda_k/\mu_{1,k}\big) \\
    w &= \operatorname{soft}\big(Dx-\alpha,\ m^{\mathrm{nl}}_k \odot \eta_k/\mu_{2,k}\big) \\
    e &= Q \odot \operatorname{soft}\big(y-Kx,\ m^{\gamma}_k \odot \gamma_k\big)

with :math:`m = \exp(c \tanh(r))`, :math:`r` the network's output for layer :math:`k` and :math:`c = \log R`,
``R = RestorerConfig.guidance_range`` (default 4: every multiplier in [1/4, 4]). ``m^tv`` and ``m^nl`` have one
channel per gradient direction (horizontal, vertical).
The multipliers act on elementwise quantities only, so the linear system of the x-update (and its CG) is the
scalar model's. The last layer of every head is zero-initialised: the untrained network multiplies by exactly 1,
and the model starts from the scalar one, bit for bit.

Architecture (``C = channels``): the colour image, centred, goes through two 3×3 convolutions once per forward
(:meth:`GuidanceNet.encode_guide`); each layer adds a 3×3 convolution of five features of its current state
(``log(1+|Dx|)`` in both directions, the estimate minus its 5×5 mean, the trusted set ``Q`` and the residual
``y − Kx`` on measured pixels, the last two compressed by ``tanh(·/4)``; all without gradient), then one shared
3×3 convolution and a per-layer 1×1 head with five outputs. The state is in the model's normalised units (the
noise σ), so the features do not depend on the depth's unit.
"""
from __future__ import annotations

import math
from typing import NamedTuple, Optional

import torch
import torch.nn.functional as F
from torch import nn

from .operators import grad
from .precision import network_autocast, uses_bfloat16

__all__ = ["GuidanceMaps", "GuidanceNet", "MAX_LOG_MULTIPLIER", "NoGuidance", "PreparedGuidance", "STATE_FEATURES",
           "UnitMultipliers"]

STATE_FEATURES = 5
"""Channels of the per-layer state features (see :meth:`GuidanceNet.state_features`)."""

MAX_LOG_MULTIPLIER = math.log(4.0)
"""The default ``c``: every multiplier lies in ``[exp(-c), exp(c)]`` = [1/4, 4] (``RestorerConfig.guidance_range``
sets ``exp(c)``)."""


class GuidanceMaps(NamedTuple):
    """Per-pixel multipliers of one layer's thresholds (all 1 for the untrained network).

    ``tv`` (B,2,H,W) multiplies λ/μ₁ per gradient direction, ``nonlocal_`` (B,2,H,W) η/μ₂, ``outlier`` (B,1,h,w)
    γ on the observation grid.
    """

    tv: torch.Tensor
    nonlocal_: torch.Tensor
    outlier: torch.Tensor

    def tv_threshold(self, threshold: torch.Tensor, isotropic: bool) -> torch.Tensor:
        """λ/μ₁ per pixel; the group (isotropic) threshold takes the geometric mean of the two directions'."""
        return threshold * (self.tv.prod(1, keepdim=True).sqrt() if isotropic else self.tv)

    def nonlocal_threshold(self, threshold: torch.Tensor) -> torch.Tensor:
        return threshold * self.nonlocal_

    def outlier_threshold(self, threshold: torch.Tensor) -> torch.Tensor:
        return threshold * self.outlier


class UnitMultipliers:
    """The thresholds of a model without a guidance network: as they are (no operation, so gradients flow as in the
    scalar model)."""

    def tv_threshold(self, threshold: torch.Tensor, isotropic: bool) -> torch.Tensor:
        return threshold

    def nonlocal_threshold(self, threshold: torch.Tensor) -> torch.Tensor:
        return threshold

    def outlier_threshold(self, threshold: torch.Tensor) -> torch.Tensor:
        return threshold


class NoGuidance:
    """What the layers ask for their thresholds' multipliers when the model has no guidance network."""

    def maps(self, index: int, x: torch.Tensor, q: torch.Tensor, residual: torch.Tensor,
             observed: torch.Tensor) -> UnitMultipliers:
        return UnitMultipliers()


class GuidanceNet(nn.Module):
    """The guidance network of :mod:`torch_depth_sr.guidance` for a model of ``num_layers`` layers.

    Args:
        num_layers: number of unrolled layers (one output head each).
        channels: feature channels of the convolutions.
        max_multiplier: ``R``, every multiplier lies in ``[1/R, R]`` (``RestorerConfig.guidance_range``).
        precision: the convolutions' arithmetic (:mod:`torch_depth_sr.precision`: ``"auto"``, ``"float32"`` or
            ``"bfloat16"``).

    Examples:
        >>> net = GuidanceNet(num_layers=2, channels=8)
        >>> sum(p.numel() for p in net.parameters())
        1850
        >>> rgb, x = torch.rand(1, 3, 16, 16), torch.randn(1, 1, 16, 16)
        >>> maps = net.prepare(rgb).maps(0, x, torch.ones_like(x), torch.zeros_like(x))
        >>> bool((maps.tv == 1).all() and (maps.outlier == 1).all())
        True
    """

    outputs = 5  # tv (2 directions), nonlocal (2 directions), outlier

    def __init__(self, num_layers: int, channels: int = 16, max_multiplier: float = 4.0, precision: str = "auto"):
        super().__init__()
        self.precision = precision
        if num_layers < 1 or channels < 1:
            raise ValueError(f"GuidanceNet needs num_layers >= 1 and channels >= 1; got {num_layers}, {channels}.")
        if not (math.isfinite(max_multiplier) and max_multiplier >= 1):
            raise ValueError(f"GuidanceNet needs a finite max_multiplier >= 1; got {max_multiplier}.")
        self.max_log_multiplier = math.log(max_multiplier)  # c: log-multipliers are c·tanh(r)
        c = channels
        # in-place ReLUs: the same values without a new plane each (autograd keeps the output it needs)
        self.guide = nn.Sequential(_conv(3, c, 3), nn.ReLU(inplace=True), _conv(c, c, 3), nn.ReLU(inplace=True))
        self.state = _conv(STATE_FEATURES, c, 3)
        self.mix = _conv(c, c, 3)
        self.heads = nn.ModuleList(nn.Conv2d(c, self.outputs, 1) for _ in range(num_layers))
        for h in self.heads:  # the untrained network multiplies every threshold by exactly 1
            nn.init.zeros_(h.weight)
            nn.init.zeros_(h.bias)

    def encode_guide(self, rgb: Optional[torch.Tensor], like: torch.Tensor) -> torch.Tensor:
        """Colour features ``(B,C,H,W)`` of ``rgb (B,3,H,W)`` in [0,1] (a mid-grey image when None), on the grid of
        ``like (B,1,H,W)``, in the network's own dtype (bfloat16 when :meth:`prepare` runs it under its precision's
        autocast): a float64 input runs the float32 network of a shipped model in float32, and
        :meth:`PreparedGuidance.maps` returns the multipliers in the input's dtype."""
        b, _, h, w = like.shape
        if rgb is None:
            rgb = like.new_full((b, 3, h, w), 0.5)
        # channels-last (here and in raw): on the CPU oneDNN's kernels for these thin convolutions are about 1.5 times
        # as fast as with the default layout (the same sums in another order)
        return self.guide((rgb.to(self.mix.weight.dtype) - 0.5).contiguous(memory_format=torch.channels_last))

    @staticmethod
    @torch.no_grad()
    def state_features(x: torch.Tensor, q: torch.Tensor, residual: torch.Tensor) -> torch.Tensor:
        """The five state features ``(B,5,H,W)`` of the estimate ``x (B,1,H,W)`` (normalised units), the trusted
        set ``q`` and the residual ``y − Kx`` on measured pixels (both (B,1,h,w), upsampled by repetition to the
        output grid when coarser); computed without gradient."""
        x = x.detach()
        s = x.shape[-1] // q.shape[-1]
        if s > 1:
            q = F.interpolate(q.detach(), scale_factor=s, mode="nearest")
            residual = F.interpolate(residual.detach(), scale_factor=s, mode="nearest")
        mean = F.avg_pool2d(F.pad(x, (2, 2, 2, 2), mode="replicate"), 5, stride=1)
        feats = [torch.log1p(grad(x).abs()), torch.tanh((x - mean) / 4), q.to(x.dtype), torch.tanh(residual / 4)]
        return torch.cat(feats, 1)  # (B,5,H,W)

    def raw(self, index: int, guide_features: torch.Tensor, state_features: torch.Tensor) -> torch.Tensor:
        """The head's output ``r (B,5,H,W)`` of layer ``index`` (the log-multipliers are ``c·tanh(r)``)."""
        state = state_features.to(guide_features.dtype).contiguous(memory_format=torch.channels_last)
        h = F.relu(guide_features + self.state(state), inplace=True)
        h = F.relu(self.mix(h), inplace=True)  # (B,C,H,W)
        return self.heads[index](h).contiguous()

    def prepare(self, rgb: Optional[torch.Tensor], like: Optional[torch.Tensor] = None) -> "PreparedGuidance":
        """Encode the colour image once per forward; the layers then ask :meth:`PreparedGuidance.maps`."""
        if like is None:
            if rgb is None:
                raise ValueError("GuidanceNet.prepare needs rgb or a depth-shaped tensor `like`.")
            like = rgb[:, :1]
        bf16 = uses_bfloat16(self.precision, self, like, *(() if rgb is None else (rgb,)))
        with network_autocast(bf16, like.device):
            return PreparedGuidance(self, self.encode_guide(rgb, like), bf16)

    def extra_repr(self) -> str:
        return (f"layers={len(self.heads)}, parameters={sum(p.numel() for p in self.parameters())}, "
                f"range=[1/{math.exp(self.max_log_multiplier):g}, {math.exp(self.max_log_multiplier):g}]")


class PreparedGuidance:
    """A :class:`GuidanceNet` with the colour features of one forward (what the layers receive)."""

    def __init__(self, net: GuidanceNet, guide_features: torch.Tensor, bfloat16: bool = False):
        self.net, self.guide_features, self.bfloat16 = net, guide_features, bfloat16

    def maps(self, index: int, x: torch.Tensor, q: torch.Tensor, residual: torch.Tensor,
             observed: Optional[torch.Tensor] = None) -> GuidanceMaps:
        """Layer ``index``'s :class:`GuidanceMaps` for the estimate ``x (B,1,H,W)``, the trusted set ``q`` and the
        residual ``(B,1,h,w)`` (times ``observed`` when given: the residual on measured pixels); the outlier map is
        averaged (in the log) to the ``(h,w)`` grid."""
        if observed is not None:
            residual = residual * observed
        feats = self.net.state_features(x, q, residual)
        with network_autocast(self.bfloat16, x.device):
            r = self.net.raw(index, self.guide_features, feats)
        if r.dtype == torch.bfloat16:  # the multipliers from the float32 value of the head's output
            r = r.float()
        log_m = self.net.max_log_multiplier * torch.tanh(r)  # (B,5,H,W)
        log_m = log_m.to(x.dtype)
        log_gamma = log_m[:, 4:5]
        s = x.shape[-1] // q.shape[-1]
        if s > 1:
            log_gamma = F.avg_pool2d(log_gamma, s)  # (B,1,h,w)
        return GuidanceMaps(tv=log_m[:, 0:2].exp(), nonlocal_=log_m[:, 2:4].exp(), outlier=log_gamma.exp())


def _conv(cin: int, cout: int, k: int) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, k, padding=k // 2, padding_mode="replicate")
