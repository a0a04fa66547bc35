r"""Initial hole fill :math:`x^0` by push-pull normalised convolution.

Missing pixels get the mask-weighted average of a coarser level of a Gaussian-like
pyramid (2×2 box "push"), pulled back up with bilinear interpolation. Measured pixels
are kept exactly. It is a fast, smooth, parameter-free fill; the restoration model
then refines the filled values with its regularisers.
"""
from __future__ import annotations

import functools
from typing import NamedTuple, Optional

import torch
import torch.nn.functional as F

from ._checks import check_4d, check_same_hw
from .native import cpu_kernel, host_path

__all__ = ["fill_holes", "pull_push", "SidedFill", "fill_holes_sided"]


def fill_holes(depth: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    r"""Fill the pixels where ``mask == 0`` by push-pull normalised convolution.

    .. math::
        x^0_i = y_i \ \text{if } m_i = 1, \qquad
        x^0_i = \uparrow\!\Big(\frac{\downarrow(m\,y)}{\downarrow m}\Big)_i \ \text{otherwise},

    applied recursively over a pyramid until every pixel has support (:func:`pull_push`, bilinear).

    Args:
        depth: ``(B,1,H,W)`` depth; values where ``mask == 0`` are ignored.
        mask: ``(B,1,H,W)`` with 1 = measured, 0 = missing. Each sample needs at least one measured pixel.

    Returns:
        ``(B,1,H,W)`` filled depth (a new tensor), equal to ``depth`` where ``mask == 1``.

    Examples:
        >>> y = torch.tensor([[[[1., 0., 3.]]]]); m = (y > 0).float()
        >>> fill_holes(y, m)
        tensor([[[[1., 2., 3.]]]])
    """
    check_4d(depth, "depth", 1)
    check_4d(mask, "mask", 1)
    check_same_hw(depth, mask, "depth", "mask")
    mask = mask.to(depth.dtype)
    return pull_push(depth, mask, upsample="bilinear")


def pull_push(values: torch.Tensor, weight: torch.Tensor, upsample: str = "bilinear") -> torch.Tensor:
    r"""Fill the pixels with zero weight from a pull-push pyramid of weighted means.

    Pull: 2×2 sums of :math:`w\,v` and :math:`w` (ceil mode keeps an odd last row/column), down to
    the level where every pixel has weight (or to 1×1). Push: each level's means :math:`\sum wv/\sum w`
    are kept where the level has weight, the others take the next coarser level interpolated
    (``"bilinear"``, ``align_corners=False``, as :func:`fill_holes`; or ``"nearest"``, as the guided
    filters' fallback). One implementation for both, so there is one pull-push in the library.

    Args:
        values: ``(B,C,H,W)`` values, only read where ``weight > 0``.
        weight: ``(B,1,H,W)`` non-negative weights.
        upsample: ``"bilinear"`` or ``"nearest"``.

    Returns:
        ``(B,C,H,W)``: ``values·w/w`` (``values`` for {0,1} weights) where ``weight > 0``, the pyramid
        elsewhere; 0 where a sample has no weight at all.
    """
    if upsample not in ("bilinear", "nearest"):
        raise ValueError(f"upsample must be 'bilinear' or 'nearest'; got {upsample!r}.")
    weighted = torch.where(weight > 0, values * weight, torch.zeros_like(values))
    return _push_pull(weighted, weight, upsample)


def _push_pull(weighted: torch.Tensor, weight: torch.Tensor, upsample: str) -> torch.Tensor:
    """Recursive push-pull on (sum of weighted values, sum of weights)."""
    h, w = weighted.shape[-2:]
    estimate = weighted / weight.clamp_min(1e-12)
    if h <= 1 and w <= 1:
        return estimate
    # the CPU stops at the first level where every pixel has weight; other devices go on to 1×1 (asking would make
    # the host wait for the device) and keep this level's estimate where it has weight: the same values
    cpu = host_path(weighted.device)
    if cpu and bool((weight > 0).all()):
        return estimate
    # push: 2x2 sums (ceil mode keeps the last odd row/column)
    coarse_weighted = F.avg_pool2d(weighted, 2, ceil_mode=True) * 4  # (B,C,ceil(H/2),ceil(W/2))
    coarse_weight = F.avg_pool2d(weight, 2, ceil_mode=True) * 4  # (B,1,ceil(H/2),ceil(W/2))
    coarse = _push_pull(coarse_weighted, coarse_weight, upsample)
    # pull: back to this level; keep the pixels that have support here
    if upsample == "bilinear":
        up = F.interpolate(coarse, size=(h, w), mode="bilinear", align_corners=False)
    else:
        up = F.interpolate(coarse, size=(h, w), mode="nearest")
    if not cpu:
        return torch.where(weight > 0, estimate, up)
    has = (weight > 0).to(estimate.dtype)
    return has * estimate + (1 - has) * up


# --------------------------------------------------------------------------------------------
# depth-gap-aware fill: holes at a discontinuity take the values of ONE side, never a mixture
# --------------------------------------------------------------------------------------------
class SidedFill(NamedTuple):
    """Result of :func:`fill_holes_sided` (all ``(B,1,H,W)``)."""

    depth: torch.Tensor  # filled depth, equal to the input where measured
    confident: torch.Tensor  # {0,1}: 1 where measured or filled with a clear side
    gap: torch.Tensor  # {0,1}: 1 at hole pixels whose neighbourhood spans a depth gap
    share: torch.Tensor  # weight share of the chosen side (1 where no gap)


def fill_holes_sided(depth: torch.Tensor, mask: torch.Tensor, rgb: Optional[torch.Tensor] = None, *,
                     kernel_size: int = 11, sigma_space: float = 6.0, sigma_color: float = 0.025,
                     gap: float = 4.0, min_share: float = 0.75, passes: int = 8,
                     quantiles: tuple = (0.1, 0.9), choice_sigma_space: Optional[float] = None) -> SidedFill:
    r"""Fill holes without bridging depth gaps: each hole takes the values of one side of an edge.

    For every hole pixel :math:`p` the measured pixels :math:`q` of its ``kernel_size`` window
    (weights :math:`w_q = f_s(\|p-q\|)\,f_c(\|I_p-I_q\|)`, Gaussian in space and colour, as the
    masked joint bilateral filter) are examined:

    * If their spread (``quantiles`` of the measured values) is at most ``gap`` (in the units of
      ``depth``; the model passes depth normalised by the noise σ, so it is ``gap`` σ), the window
      holds one surface and the pixel gets the plain weighted mean (masked JBF).
    * Otherwise the window spans a depth gap. Its measured values are split into two sides by
      2-means (seeded at the two quantiles); values in the middle third between the two side means
      (flying pixels) are dropped. The pixel takes the side with the larger weight mass
      :math:`\sum_{q \in \text{side}} w_q` (colour similarity and nearness: a sensor shadow has the
      colour of the background it lies on, so it is filled from the background) and the weighted
      mean of that side only. It is *confident* when that side holds at least ``min_share`` of
      the mass, otherwise the side is a guess and ``confident`` is 0 there.

    Holes deeper than the window are filled in up to ``passes`` rounds, each treating the pixels
    filled so far as measured (so the sides keep propagating apart, and a pixel filled from an
    unconfident one is unconfident too); what is left after that is filled by push-pull
    (:func:`fill_holes`) and marked unconfident. The rule needs no convention for which way
    depth grows (depth or disparity): the side is chosen by colour and nearness, not by value.

    Args:
        depth: ``(B,1,H,W)``; values where ``mask == 0`` are ignored.
        mask: ``(B,1,H,W)``, 1 = measured.
        rgb: ``(B,3,H,W)`` guide in [0,1], or None (then the side is chosen by nearness alone).
        kernel_size: odd window size (px).
        sigma_space, sigma_color: Gaussian widths in px and in [0,1] colour units (L2 over RGB).
        gap: spread above which a window counts as spanning a depth gap (depth units).
        min_share: weight share of the chosen side needed to call the fill confident.
        passes: propagation rounds before the push-pull fallback.
        quantiles: the low/high quantiles of the measured values that measure the spread.

    Returns:
        :class:`SidedFill` ``(depth, confident, gap)``.

    Examples:
        >>> y = torch.zeros(1, 1, 8, 12); y[..., :, :6] = 10.; y[..., :, 7:] = 50.  # column 6 missing
        >>> rgb = torch.zeros(1, 3, 8, 12); rgb[:, :, :, 6:] = 1.  # the hole has the right side's colour
        >>> r = fill_holes_sided(y, (y > 0).float(), rgb, kernel_size=5)
        >>> r.depth[0, 0, 0, 6].item(), r.confident[0, 0, 0, 6].item()
        (50.0, 1.0)
    """
    check_4d(depth, "depth", 1)
    check_4d(mask, "mask", 1)
    check_same_hw(depth, mask, "depth", "mask")
    if kernel_size < 3 or kernel_size % 2 == 0:
        raise ValueError(f"kernel_size must be an odd int >= 3; got {kernel_size}.")
    b, _, h, w = depth.shape
    dt = depth.dtype
    # the planes the passes fill in place, C-contiguous whatever the inputs' strides (the CPU loop writes them through
    # one flat index, the kernel reads them as flat arrays)
    known = (mask > 0).contiguous()
    x = torch.where(known, depth, torch.zeros_like(depth)).contiguous()
    conf = known.to(dt)
    gapped = torch.zeros_like(conf)
    shares = torch.ones_like(conf)
    filled = known.clone()
    r = kernel_size // 2
    dy, dx = torch.meshgrid(torch.arange(-r, r + 1, device=depth.device), torch.arange(-r, r + 1, device=depth.device),
                            indexing="ij")
    dy, dx = dy.reshape(-1), dx.reshape(-1)
    ws = torch.exp(-(dy ** 2 + dx ** 2).to(dt) / (2 * sigma_space ** 2))  # (K²,)
    wch = ws if choice_sigma_space is None else torch.exp(-(dy ** 2 + dx ** 2).to(dt) / (2 * choice_sigma_space ** 2))
    guide = None if rgb is None else rgb.to(dt)
    # the guide with its channels last, one row per pixel: every gather below takes rows of it by flat pixel index
    # (one index tensor instead of four: the same values, several times faster than multi-dimensional indexing)
    guide_rows = None if guide is None else guide.expand(b, -1, h, w).permute(0, 2, 3, 1).reshape(b * h * w, -1)
    allow_weak = guide is None
    planes = _FillPlanes(x, conf, filled, guide_rows, ws, wch, dy, dx, h, w, sigma_color, quantiles, gap, min_share,
                         guide)
    if not host_path(depth.device):
        return _fill_every_pixel(planes, gapped, shares, passes, allow_weak)
    # the numba kernel computes each pass's pixels as _fill_pixels does (no gradient through it)
    tracked = torch.is_grad_enabled() and (depth.requires_grad or (rgb is not None and rgb.requires_grad))
    kernel = _kernel() if not tracked and dt in (torch.float32, torch.float64) else None
    fill_pass = _fill_pixels if kernel is None else kernel
    if kernel is not None and guide is not None:  # the kernel reads the guide's planes as one C-contiguous array
        planes = planes._replace(guide=guide.contiguous())
    bi, _, yi, xi = torch.nonzero(~filled, as_tuple=True)  # (N,) the pixels to fill, kept up to date below
    for _ in range(max(1, passes) + 1):
        if bi.numel() == 0:
            break
        est, c_new, spans, share, ok, weak = fill_pass(planes, bi, yi, xi)
        if not allow_weak:
            if not bool((ok & ~weak).any()):
                allow_weak = True
                continue
            ok = ok & ~weak
        flat = ((bi * h + yi) * w + xi)[ok]  # one index into the (B,1,H,W) planes: several times faster than four
        x.view(-1)[flat] = est[ok]
        conf.view(-1)[flat] = c_new[ok]
        gapped.view(-1)[flat] = spans[ok].to(dt)
        shares.view(-1)[flat] = torch.where(spans, share, torch.ones_like(share))[ok]
        filled.view(-1)[flat] = True
        left = ~ok  # those still unfilled, in the order of nonzero(~filled)
        bi, yi, xi = bi[left], yi[left], xi[left]
    if not bool(filled.all()):
        rest = fill_holes(x, filled.to(dt))
        x = torch.where(filled, x, rest)
    return SidedFill(x, conf, gapped, shares)


def _kernel():
    """The numba kernel of one pass (:func:`~torch_depth_sr.fill_kernel.fill_pixels_cpu`), or None (see
    :mod:`torch_depth_sr.native`)."""
    kernel = cpu_kernel("fill_kernel", "fill_pixels_cpu")
    return None if kernel is None else functools.partial(kernel, match=_MATCH)


class _FillPlanes(NamedTuple):
    """What every pass of :func:`fill_holes_sided` reads: the planes it fills in place (``x``, ``conf``, ``filled``)
    and the fixed settings."""

    x: torch.Tensor
    conf: torch.Tensor
    filled: torch.Tensor
    guide_rows: Optional[torch.Tensor]
    ws: torch.Tensor
    wch: torch.Tensor
    dy: torch.Tensor
    dx: torch.Tensor
    h: int
    w: int
    sigma_color: float
    quantiles: tuple
    gap: float
    min_share: float
    guide: Optional[torch.Tensor] = None  # (1 or B, C, H, W): the guide planes ``guide_rows`` holds, read by the kernel


def _fill_pixels(p: _FillPlanes, bi: torch.Tensor, yi: torch.Tensor, xi: torch.Tensor) -> tuple:
    """One pass's values at the pixels ``(bi, yi, xi)`` (N,) from their windows: ``(estimate, confidence, spans a
    gap, side share, has a value, weak)``, each (N,). Each pixel's values depend on its window only."""
    h, w, dt = p.h, p.w, p.x.dtype
    yy = (yi[:, None] + p.dy[None]).clamp(-1, h)  # (N, K²); -1 / h = outside
    xx = (xi[:, None] + p.dx[None]).clamp(-1, w)
    inside = (yy >= 0) & (yy < h) & (xx >= 0) & (xx < w)
    yc, xc = yy.clamp(0, h - 1), xx.clamp(0, w - 1)
    flat = (bi[:, None] * h + yc) * w + xc  # (N, K²) flat index of each window pixel in (B, 1, H, W)
    v = p.x.reshape(-1)[flat]  # (N, K²)
    m = (p.filled.reshape(-1)[flat] & inside).to(dt)
    c = p.conf.reshape(-1)[flat]
    wgt = p.ws[None] * m
    wc = torch.ones_like(m)
    if p.guide_rows is not None:
        centre = p.guide_rows[(bi * h + yi) * w + xi]  # (N, 3)
        d2 = (p.guide_rows[flat] - centre[:, None, :]).pow(2).sum(-1)  # (N, K², 3) -> (N, K²)
        wc = torch.exp(-d2 / (2 * p.sigma_color ** 2))
        wgt = wgt * wc
    has = m.sum(1) > 0
    # pixels none of whose measured neighbours has a similar colour wait for the propagation from the side
    # they match; only when a pass fills nothing else are they filled by nearness (space weights) alone
    weak = (wc * m).amax(1) < _MATCH if p.guide_rows is not None else torch.zeros_like(has)
    wgt = torch.where(weak[:, None], p.ws[None] * m, wgt)
    # spread of the measured values
    vn = torch.where(m > 0, v, torch.full_like(v, float("nan")))
    lo, hi = _nanquantiles(vn, p.quantiles)
    spans = has & (hi - lo > p.gap)
    # 2-means seeded at the quantiles
    ca, cb = lo, hi
    for _it in range(2):
        mid = 0.5 * (ca + cb)
        in_b = (v > mid[:, None]) & (m > 0)
        in_a = (v <= mid[:, None]) & (m > 0)
        ca = _masked_mean(v, in_a, ca)
        cb = _masked_mean(v, in_b, cb)
    third = (cb - ca) / 3
    side_a = in_a & (v <= (ca + third)[:, None])
    side_b = in_b & (v >= (cb - third)[:, None])
    wchoice = p.wch[None] * m * wc
    wchoice = torch.where(weak[:, None], p.wch[None] * m, wchoice)
    wa = (wchoice * side_a).sum(1)
    wb = (wchoice * side_b).sum(1)
    pick_b = wb > wa
    side = torch.where(pick_b[:, None], side_b, side_a)
    share = torch.maximum(wa, wb) / (wa + wb).clamp_min(1e-30)
    use = torch.where(spans[:, None], side.to(dt), torch.ones_like(m)) * wgt
    den = use.sum(1)
    est = (use * v).sum(1) / den.clamp_min(1e-30)
    ok = has & (den > 0)
    c_in = (use * c).sum(1) / den.clamp_min(1e-30)  # confidence of what the value came from
    c_new = torch.where(spans, (share >= p.min_share).to(dt), torch.ones_like(share)) * (c_in > 0.5).to(dt)
    return est, c_new, spans, share, ok, weak


_FILL_CHUNK = 1 << 16  # pixels per window gather off the CPU: 65536 × 121 × 3 × 4 bytes ≈ 95 MB for the colour


def _fill_every_pixel(p: _FillPlanes, gapped: torch.Tensor, shares: torch.Tensor, passes: int,
                      allow_weak: bool) -> SidedFill:
    """:func:`fill_holes_sided`'s passes without reading a value on the host (any device): every pixel is computed
    (in chunks of the same size whatever the holes) and the holes' results are kept, so the pixels filled and
    their values are those of the CPU path, which computes the holes only. A pass with nothing to fill changes
    nothing; the switch to weak pixels (when a pass fills nothing else) is a flag on the device."""
    b, dt = p.x.shape[0], p.x.dtype
    n = b * p.h * p.w
    pixel = torch.arange(n, device=p.x.device)
    bi, yi, xi = pixel // (p.h * p.w), pixel // p.w % p.h, pixel % p.w
    x, conf, filled = p.x.reshape(-1), p.conf.reshape(-1), p.filled.reshape(-1)
    gapped, shares = gapped.reshape(-1), shares.reshape(-1)
    weak_allowed = torch.full((), bool(allow_weak), device=p.x.device)  # a fill, not a host copy: graphs capture it
    for _ in range(max(1, passes) + 1):
        parts = [_fill_pixels(p, bi[i:i + _FILL_CHUNK], yi[i:i + _FILL_CHUNK], xi[i:i + _FILL_CHUNK])
                 for i in range(0, n, _FILL_CHUNK)]
        est, c_new, spans, share, ok, weak = (torch.cat(t) for t in zip(*parts))
        ok = ok & ~filled
        stalled = ~weak_allowed & ~(ok & ~weak).any()  # the CPU's "continue": nothing written, weak pixels next
        ok = ok & ~stalled & (weak_allowed | ~weak)
        weak_allowed = weak_allowed | stalled
        x = torch.where(ok, est, x)
        conf = torch.where(ok, c_new, conf)
        gapped = torch.where(ok, spans.to(dt), gapped)
        shares = torch.where(ok & spans, share, torch.where(ok, torch.ones_like(share), shares))
        filled = filled | ok
        p = p._replace(x=x.view_as(p.x), conf=conf.view_as(p.conf), filled=filled.view_as(p.filled))
    x, filled = p.x, p.filled
    x = torch.where(filled, x, fill_holes(x, filled.to(dt)))
    return SidedFill(x, p.conf, gapped.view_as(x), shares.view_as(x))


_MATCH = 1e-3  # colour weight above which a neighbour "looks like" the pixel (distance < 3.7 sigma_color)


def _nanquantiles(v: torch.Tensor, qs) -> list:
    """Row-wise quantiles (nearest rank) of ``v (N,K)`` ignoring NaN; NaN rows give 0."""
    n = (~torch.isnan(v)).sum(1)
    s = torch.sort(torch.nan_to_num(v, nan=float("inf")), dim=1).values
    out = []
    for qq in qs:
        k = ((n - 1).clamp_min(0).to(v.dtype) * qq).round().long()
        val = s.gather(1, k[:, None])[:, 0]
        out.append(torch.where(n > 0, val, torch.zeros_like(val)))
    return out


def _masked_mean(v: torch.Tensor, sel: torch.Tensor, default: torch.Tensor) -> torch.Tensor:
    cnt = sel.sum(1)
    mean = (v * sel).sum(1) / cnt.clamp_min(1)
    return torch.where(cnt > 0, mean, default)
