r"""Noise level estimation and the depth scale policy.

**Scale policy.** The model never sees raw units. Each sample is normalised as

.. math::  y_n = (y - m) / \hat\sigma,

with :math:`m` the median of the measured depth and :math:`\hat\sigma` the noise level
estimated on measured pixels. Every threshold and weight of the model (λ, η, γ, the
singular-pixel σ floor, block-matching temperature) is therefore expressed in multiples
of the noise level, and one parameter set serves disparity in pixels, millimetres and
metres alike: restoring ``1000·y`` gives exactly ``1000·`` the result.

The noise level is the robust (MAD) standard deviation of second differences
:math:`y_{i-1} - 2y_i + y_{i+1}` over triplets of measured pixels in both directions;
second differences cancel planar slopes, and the median ignores depth edges,
flying pixels and impulses. For a Gaussian noise of std σ, the second difference has
std :math:`\sqrt 6\,σ`.

**Quantisation floor.** Depth stored as integers (8-bit disparity, 16-bit millimetres) carries at
least the rounding error of its grid, uniform on ±step/2, i.e. a std of step/√12. On clean integer
maps more than half of the second differences are exactly 0, so the MAD is 0; the estimate is
therefore floored at step/√12 (:func:`quantisation_step` finds the step).
"""
from __future__ import annotations

import torch

from .native import host_path
from .selection import distinct, kth_smallest, lower_median
from .window_max import max_filter

__all__ = ["depth_scale", "estimate_noise_sigma", "implausible", "policy_scale", "quantisation_step",
           "sample_percentiles", "sampled_noise_sigma", "white_noise_sigma"]

_MAD_TO_STD = 1.4826
# Patch PCA over second differences on clean maps resampled from integer depth (the eleven Middlebury 2006 images of
# the guided-SR test set, Pillow-bicubic x4: 0.34-0.46, x8: 0.37-0.56; 0.6 lets Cloth1 x8 pass, issue 12); under white
# noise: 1
_WHITE_RATIO_CLEAN = 0.6


def estimate_noise_sigma(depth: torch.Tensor, observed: torch.Tensor, method: str = "second_differences"
                         ) -> torch.Tensor:
    """Estimate the per-sample noise std of ``depth (B,1,H,W)`` on ``observed`` pixels.

    ``method="second_differences"`` (the model's): MAD of the horizontal and vertical second differences of
    measured triplets (planes give 0). ``"haar"`` (the dictionary baseline's, Donoho & Johnstone 1994):
    median |HH| / 0.6745 of the Haar diagonal detail ``(x00 − x01 − x10 + x11)/2`` over non-overlapping 2×2
    blocks whose four pixels are measured.

    Returns ``(B,)`` in the units of ``depth``. Samples with too few measured triplets (fewer than 16; for
    ``"haar"`` no complete block) or a perfectly smooth surface get 0; callers floor it (see :func:`depth_scale`).

    Examples:
        >>> g = torch.Generator().manual_seed(0)
        >>> y = 100 + 5 * torch.randn(1, 1, 200, 200, generator=g)
        >>> round(float(estimate_noise_sigma(y, torch.ones_like(y))), 1)
        5.0
        >>> round(float(estimate_noise_sigma(y, torch.ones_like(y), method="haar")))
        5
    """
    if method == "haar":
        return _haar_sigma(depth, observed)
    if method != "second_differences":
        raise ValueError(f"method must be 'second_differences' or 'haar'; got {method!r}.")
    d = depth.detach()
    m = observed > 0
    dh = d[..., :, :-2] - 2 * d[..., :, 1:-1] + d[..., :, 2:]
    mh = m[..., :, :-2] & m[..., :, 1:-1] & m[..., :, 2:]
    dv = d[..., :-2, :] - 2 * d[..., 1:-1, :] + d[..., 2:, :]
    mv = m[..., :-2, :] & m[..., 1:-1, :] & m[..., 2:, :]
    return _second_difference_mad(dh, mh, dv, mv, depth)


def _second_difference_mad(dh, mh, dv, mv, like: torch.Tensor) -> torch.Tensor:
    """(B,): the noise std from the MAD of the measured second differences ``dh``, ``dv`` (masks ``mh``, ``mv``); 0
    for a sample with fewer than 16."""
    out = like.new_zeros(like.shape[0])
    if not host_path(like.device):  # every sample at once, no value read on the host: the same medians
        vals, n = _sorted_rows(torch.cat([dh.flatten(1), dv.flatten(1)], 1).abs(),
                               torch.cat([mh.flatten(1), mv.flatten(1)], 1))
        return torch.where(n >= 16, _MAD_TO_STD * _lower_median(vals, n) / 6**0.5, out)
    for i in range(like.shape[0]):
        vals = torch.cat([dh[i][mh[i]], dv[i][mv[i]]]).abs()
        if vals.numel() >= 16:
            out[i] = _MAD_TO_STD * lower_median(vals) / 6**0.5
    return out


def sampled_noise_sigma(depth: torch.Tensor, observed: torch.Tensor, phase: int, every: int = 4) -> torch.Tensor:
    """:func:`estimate_noise_sigma` (second differences) from the rows ``phase, phase + every, …`` only: the
    horizontal triplets of those rows and the vertical triplets centred on them (``1 <= phase < every``). A
    quarter of the work for ``every = 4``, and as many times the variance; a stream averages it over frames whose
    phases cycle through the rows (:class:`~torch_depth_sr.stream.StreamRestorer`)."""
    h = depth.shape[-2]
    n = len(range(phase, h - 1, every))
    if n == 0:
        return estimate_noise_sigma(depth, observed)
    d, m = depth.detach(), observed > 0
    rows = [slice(phase + k, phase + k + every * (n - 1) + 1, every) for k in (-1, 0, 1)]
    up, mid, down = (d[..., r, :] for r in rows)
    mu, mm, md = (m[..., r, :] for r in rows)
    dh = mid[..., :, :-2] - 2 * mid[..., :, 1:-1] + mid[..., :, 2:]
    mh = mm[..., :, :-2] & mm[..., :, 1:-1] & mm[..., :, 2:]
    return _second_difference_mad(dh, mh, up - 2 * mid + down, mu & mm & md, depth)


def white_noise_sigma(depth: torch.Tensor, observed: torch.Tensor, patch: int = 5) -> torch.Tensor:
    r"""The level ``(B,)`` of the white (pixel-independent) noise in ``depth (B,1,H,W)``, in its units.

    Fine surface texture (cloth ripples, the staircase of a resampled integer map) has second differences of the
    noise level too, so :func:`estimate_noise_sigma` ``σ_d`` takes it for noise; but it is smooth, so it lives in a
    few directions of the space of ``patch × patch`` patches, while white noise spreads evenly over all of them.
    The smallest non-zero eigenvalue of the covariance of mean-removed patches (Liu et al. 2012), Marchenko-Pastur
    corrected, gives ``σ_p``; patches with a second difference beyond 4 σ_d (edges) are left out. Texture still
    leaks into ``σ_p``, less than into ``σ_d`` (``σ_p ≤ ρ σ_d`` on clean maps, ``ρ = 0.6``; equal under white
    noise), so with ``σ_d² = n² + S²`` and ``σ_p² = n² + ρ² S²``:

    .. math::  n = \sqrt{\max(σ_p^2 - ρ^2 σ_d^2,\ 0) / (1 - ρ^2)}.

    A sample with fewer than ``2 patch²`` complete patches gets ``σ_d``.

    Examples:
        >>> g = torch.Generator().manual_seed(0)
        >>> yy, xx = torch.meshgrid(torch.arange(120.0), torch.arange(120.0), indexing="ij")
        >>> ripples = (100 + 0.6 * torch.sin(1.1 * xx + 0.3 * yy) + 0.4 * torch.sin(0.4 * xx - 0.9 * yy + 1))[None, None]
        >>> one = torch.ones_like(ripples)
        >>> round(float(estimate_noise_sigma(ripples, one)), 2), float(white_noise_sigma(ripples, one))
        (0.16, 0.0)
        >>> abs(float(white_noise_sigma(ripples + 2 * torch.randn(ripples.shape, generator=g), one)) - 2) < 0.2
        True
    """
    sd = estimate_noise_sigma(depth, observed)
    if min(depth.shape[-2:]) < patch:  # no complete patch at all
        return sd
    d = depth.detach().double()
    m = (observed > 0).to(d.dtype)
    dh = torch.zeros_like(d)
    dv = torch.zeros_like(d)
    dh[..., :, 1:-1] = (d[..., :, :-2] - 2 * d[..., :, 1:-1] + d[..., :, 2:]).abs()
    dv[..., 1:-1, :] = (d[..., :-2, :] - 2 * d[..., 1:-1, :] + d[..., 2:, :]).abs()
    dmax = max_filter(torch.maximum(dh, dv), patch, padding=0)
    complete = torch.nn.functional.avg_pool2d(m, patch, stride=1) > 1 - 1e-9
    sd4 = sd.to(d).view(-1, 1, 1, 1)
    # the patches used, as weights (no boolean indexing: batched, and the host never waits for the device)
    use = (complete & (dmax <= 4 * 6**0.5 * sd4)).flatten(1).to(d.dtype)  # (B, N)
    patches = torch.nn.functional.unfold(d * m, patch)  # (B, p², N)
    q = patches - patches.mean(1, keepdim=True)  # each patch's own mean removed
    n = use.sum(1)  # (B,)
    k = patch * patch
    cov = torch.einsum("bkn,bln,bn->bkl", q, q, use) / n.clamp_min(1).view(-1, 1, 1)
    ev = torch.linalg.eigvalsh(cov)  # ascending; ev[:, 0] ≈ 0: the removed patch mean
    sp2 = ev[:, 1].clamp_min(0) / (1 - (k / n.clamp_min(k + 1)).sqrt()) ** 2  # Marchenko-Pastur correction
    ratio = _WHITE_RATIO_CLEAN
    sdd = sd.to(d)
    white = ((sp2 - ratio**2 * sdd**2).clamp_min(0) / (1 - ratio**2)).sqrt()
    enough = (n >= 2 * k) & (sdd > 0)  # too few complete patches: the second differences' estimate
    return torch.where(enough, white, sdd).to(sd.dtype)


def _haar_sigma(depth: torch.Tensor, observed: torch.Tensor) -> torch.Tensor:
    m = (observed > 0).to(depth.dtype)
    h2, w2 = depth.shape[-2] // 2 * 2, depth.shape[-1] // 2 * 2
    x = torch.where(m > 0, depth, torch.zeros_like(depth))[..., :h2, :w2]
    mm = m[..., :h2, :w2]
    hh = 0.5 * (x[..., 0::2, 0::2] - x[..., 0::2, 1::2] - x[..., 1::2, 0::2] + x[..., 1::2, 1::2])
    ok = mm[..., 0::2, 0::2] * mm[..., 0::2, 1::2] * mm[..., 1::2, 0::2] * mm[..., 1::2, 1::2]
    out = []
    for b in range(depth.shape[0]):
        v = hh[b][ok[b] > 0].abs()
        out.append(lower_median(v) / 0.6745 if v.numel() else depth.new_zeros(()))
    return torch.stack(out) if out else depth.new_zeros(0)


def quantisation_step(depth: torch.Tensor, observed: torch.Tensor, integer_input: bool = False) -> torch.Tensor:
    """Per-sample grid step ``(B,)`` of the measured values; 0 where they lie on no grid.

    Integer input has step 1 (the value grid of its dtype) or the coarser grid its values lie on (so that
    ``1000 · y`` gets step 1000 and the scale policy stays equivariant). Any input is taken to be on a grid only
    when it repeats values (fewer distinct values than a quarter of the measured pixels, which noisy
    float data never does) and every value is, to 1e-4 of the step, a multiple of the smallest gap
    between distinct values.

    Examples:
        >>> y = torch.tensor([2., 4., 6., 8.]).repeat(4).view(1, 1, 2, 8)  # 16 values on a grid of 2
        >>> quantisation_step(y, torch.ones_like(y))
        tensor([2.])
    """
    b = depth.shape[0]
    if not host_path(depth.device):
        return _grid_steps(depth.detach().double().flatten(1), observed.flatten(1) > 0, integer_input).to(depth.dtype)
    out = depth.new_zeros(b)
    for i in range(b):
        vals = depth[i][observed[i] > 0].detach().double()
        out[i] = _grid_step(vals, 1.0 if integer_input and vals.numel() else 0.0)
    return out


def _percentiles(vals: torch.Tensor) -> torch.Tensor:
    """p1 and p99 of a 1-D tensor in its own dtype (float32 would overflow at 1e200 or flush 1e-300 to 0); the host
    path (the device path: :func:`_masked_percentiles`)."""
    dt = torch.float64 if vals.dtype == torch.float64 else torch.float32
    sub = vals if vals.numel() < 16_000_000 else vals[:: max(1, vals.numel() // 1_000_000)]
    q = torch.tensor([0.01, 0.99], dtype=dt)
    if sub.numel() < 2 or bool(torch.isnan(sub).any()):
        return torch.quantile(sub.to(dt), q).to(vals.dtype)
    return _quantiles_by_selection(sub.to(dt).reshape(-1), q).to(vals.dtype)


# ---- the device path: the per-sample statistics above for every sample at once, with the shapes of the input (no
# boolean selection, no value read on the host); each gives what its CPU loop gives, bit for bit
def _sorted_rows(values: torch.Tensor, keep: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Each row of ``values (B,N)`` sorted with the kept values first (the others as +inf after them; kept values
    are finite), and the count ``(B,)`` kept."""
    inf = torch.full_like(values, float("inf"))
    return torch.where(keep, values, inf).sort(1).values, keep.sum(1)


def _lower_median(rows: torch.Tensor, n: torch.Tensor) -> torch.Tensor:
    """What ``torch.median`` gives for the first ``n`` values of each sorted row (the lower of two middles); NaN for
    none, as torch.median of nothing."""
    m = rows.gather(1, ((n - 1).clamp_min(0) // 2)[:, None])[:, 0]
    return torch.where(n > 0, m, torch.full_like(m, float("nan")))


def _masked_percentiles(values: torch.Tensor, keep: torch.Tensor, out: torch.Tensor) -> torch.Tensor:
    """:func:`_percentiles` of the kept values of each row of ``values (B,N)`` (``out (B,2)`` where fewer than two):
    the same subsample of large rows (every s-th kept value), the same ranks and interpolation."""
    dt = torch.float64 if values.dtype == torch.float64 else torch.float32
    n = keep.sum(1, keepdim=True)
    step = torch.where(n < 16_000_000, torch.ones_like(n), (n // 1_000_000).clamp_min(1))
    keep = keep & ((keep.cumsum(1) - 1) % step == 0)
    rows, m = _sorted_rows(values.to(dt), keep)
    # filled on the device, not copied from the host (nor set item by item, which copies too): a graph captures it
    q = torch.stack([torch.full((), 0.01, dtype=dt, device=values.device),
                     torch.full((), 0.99, dtype=dt, device=values.device)])
    ranks = q[None] * (m - 1).clamp_min(0).to(dt)[:, None]  # (B, 2), as q * (numel - 1)
    below, above = ranks.to(torch.long), ranks.ceil().to(torch.long)
    p = rows.gather(1, below).lerp(rows.gather(1, above), ranks - below)
    return torch.where(n > 1, p.to(values.dtype), out)


def _grid_steps(vals: torch.Tensor, keep: torch.Tensor, integer_input: bool) -> torch.Tensor:
    """:func:`_grid_step` of the kept values of each row of ``vals (B,N)`` float64, from one sort: the distinct
    values are where the sorted row changes, the smallest gap between them is the smallest positive difference."""
    rows, n = _sorted_rows(vals, keep)
    pos = torch.arange(rows.shape[1], device=rows.device)[None]
    diff = rows[:, 1:] - rows[:, :-1]
    pair = pos[:, 1:] < n[:, None]  # both values kept
    distinct = torch.where(n > 0, 1 + (pair & (diff > 0)).sum(1), n)
    step = torch.where(pair & (diff > 0), diff, torch.full_like(diff, float("inf"))).amin(1)
    ratio = rows / step[:, None]
    inside = pos < n[:, None]
    err = torch.where(inside, (ratio - ratio.round()).abs(), torch.zeros_like(ratio)).amax(1)
    big = torch.where(inside, ratio.abs(), torch.zeros_like(ratio)).amax(1)
    on_grid = (distinct >= 2) & (distinct <= n // 4) & (err < 1e-4) & (big < 2**40)
    default = torch.full_like(step, 1.0) * ((n > 0) & integer_input)
    return torch.where(on_grid, step, default)


def _quantiles_by_selection(v: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
    """``torch.quantile(v, q)`` (linear interpolation) bit for bit, from the two order statistics around each rank
    found by selection (``kthvalue``, linear time) instead of a full sort: the ranks, the interpolation weights and
    the ``lerp`` are torch.quantile's own (``ranks = q·(n−1)`` in ``v``'s dtype). ``v`` 1-D without NaN."""
    ranks = q * (v.numel() - 1)
    below, above = ranks.to(torch.long), ranks.ceil().to(torch.long)
    ks = sorted(set(below.tolist()) | set(above.tolist()))
    order = dict(zip(ks, kth_smallest(v, ks).to(v.device)))
    lo = torch.stack([order[k] for k in below.tolist()])
    hi = torch.stack([order[k] for k in above.tolist()])
    return lo.lerp(hi, (ranks - below).to(v.device))


def sample_percentiles(depth: torch.Tensor, observed: torch.Tensor) -> torch.Tensor:
    """p1 and p99 ``(B, 2)`` of each sample's measured values, in ``depth``'s dtype (0 with fewer than two): what
    :func:`depth_scale` and :func:`implausible` both read, computed once by the scale policy.

    Examples:
        >>> y = torch.arange(100.0).view(1, 1, 10, 10)
        >>> sample_percentiles(y, torch.ones_like(y))
        tensor([[ 0.9900, 98.0100]])
    """
    out = depth.new_zeros(depth.shape[0], 2)
    if not host_path(depth.device):
        return _masked_percentiles(depth.detach().flatten(1), observed.flatten(1) > 0, out)
    for i in range(depth.shape[0]):
        vals = depth[i][observed[i] > 0].detach()
        if vals.numel() > 1:
            out[i] = _percentiles(vals)
    return out


def implausible(depth: torch.Tensor, observed: torch.Tensor, scale: torch.Tensor, margin: float = 100.0,
                percentiles: torch.Tensor | None = None) -> torch.Tensor:
    """Measured pixels ``(B,1,H,W)`` bool that lie far outside every surface of their sample.

    A value beyond ``[p1 − r − margin·scale, p99 + r + margin·scale]`` (``r = p99 − p1`` of the measured
    depth, ``scale`` the noise level of the scale policy) is no surface but a glitch of the sensor or the
    file (one pixel of 1e10 among disparities). Such a pixel is treated as not measured: the restorer
    fills it like a hole and its confidence is 0, and one pixel can no longer overflow the arithmetic.
    ``percentiles``: :func:`sample_percentiles` of the same input, when the caller has them.

    Examples:
        >>> y = torch.full((1, 1, 8, 8), 100.0); y[0, 0, 3, 3] = 1e10
        >>> implausible(y, torch.ones_like(y), torch.tensor([1.0])).sum().item()
        1
    """
    out = torch.zeros_like(observed, dtype=torch.bool)
    if not host_path(depth.device):  # the same bounds, every sample at once
        m = observed > 0
        p = (percentiles if percentiles is not None else sample_percentiles(depth, observed)).view(-1, 2, 1, 1, 1)
        p1, p99 = p[:, 0], p[:, 1]
        r, s = p99 - p1, scale.view(-1, 1, 1, 1)
        lo, hi = p1 - r - margin * s, p99 + r + margin * s
        enough = m.flatten(1).sum(1).view(-1, 1, 1, 1) >= 2
        return m & enough & ((depth < lo) | (depth > hi))
    for i in range(depth.shape[0]):
        m = observed[i] > 0
        if int(m.sum()) < 2:
            continue
        p1, p99 = (percentiles[i] if percentiles is not None else _percentiles(depth[i][m].detach()))
        r = p99 - p1
        lo, hi = p1 - r - margin * scale[i], p99 + r + margin * scale[i]
        out[i] = m & ((depth[i] < lo) | (depth[i] > hi))
    return out


def _grid_step(vals: torch.Tensor, default: float) -> float:
    limit = vals.numel() // 4
    if vals.numel() >= 4096:  # more distinct values in a prefix than the limit: more in all of them (noisy float
        # data, which repeats no value), without sorting all of them
        prefix = vals.reshape(-1)[: limit + 1 + limit // 8]
        if distinct(prefix).numel() > limit:
            return default
    uniq = distinct(vals)
    if uniq.numel() < 2 or uniq.numel() > vals.numel() // 4:
        return default
    step = float((uniq[1:] - uniq[:-1]).min())
    ratio = uniq / step
    if float((ratio - ratio.round()).abs().max()) < 1e-4 and float(ratio.abs().max()) < 2**40:
        return step
    return default


def depth_scale(depth: torch.Tensor, observed: torch.Tensor, noise_sigma: float | torch.Tensor | None = None,
                relative_floor: float = 1e-3, step: torch.Tensor | None = None,
                percentiles: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Return ``(offset (B,), scale (B,), sigma (B,))`` of the scale policy.

    ``scale = max(sigma, relative_floor · (p99 − p1 of measured depth), 1e-6 · |offset|)``:
    the floors only matter for noise-free or constant inputs, and all terms are
    proportional to the depth unit, so the policy stays scale-equivariant.
    ``noise_sigma`` (float or ``(B,)``, in depth units) overrides the estimate; otherwise the estimate
    is floored at ``step/√12``, the rounding noise of a quantised grid (``step (B,)``, 0 = none).
    ``percentiles``: :func:`sample_percentiles` of the same input, when the caller has them.
    """
    b = depth.shape[0]
    if host_path(depth.device):
        offset = depth.new_zeros(b)
        for i in range(b):
            offset[i] = lower_median(depth[i][observed[i] > 0].detach())
    else:
        offset = _lower_median(*_sorted_rows(depth.detach().flatten(1), observed.flatten(1) > 0))
    q = sample_percentiles(depth, observed) if percentiles is None else percentiles
    spread = q[:, 1] - q[:, 0]
    if noise_sigma is None:
        sigma = estimate_noise_sigma(depth, observed)
        if step is not None:
            sigma = torch.maximum(sigma, step.to(sigma) / 12**0.5)
    else:
        sigma = torch.as_tensor(noise_sigma, dtype=depth.dtype, device=depth.device).expand(b).clone()
    return offset, policy_scale(sigma, spread, offset, relative_floor), sigma


def policy_scale(sigma: torch.Tensor, spread: torch.Tensor, offset: torch.Tensor,
                 relative_floor: float = 1e-3) -> torch.Tensor:
    """:func:`depth_scale`'s scale from its parts (B,): ``max(sigma, relative_floor · spread, 1e-6 · |offset|)``."""
    scale = torch.maximum(sigma, relative_floor * spread)
    scale = torch.maximum(scale, 1e-6 * offset.abs())
    return scale.clamp_min(torch.finfo(sigma.dtype).tiny)
