"""Edge snapping: move each pixel to one side of a depth edge when the colour says which side it belongs to.

A smoothing restorer leaves a pixel at a depth edge between the two surfaces (a blend), and a flying pixel the
singular test missed keeps its in-between value; both are points in the air of the point cloud. A weighted median
with colour weights picks an actual value of the side whose colour matches (OpenCV's ``weightedMedianFilter``
does this for every pixel and pays for it on smooth surfaces). Here the median only replaces a pixel where the
colour-weighted mass *on the median's side of the pixel's own value* is a clear majority (``share``): a blend
between two surfaces whose colours are told apart moves to its side, a pixel whose window has no such majority
(ambiguous colour, or a smooth surface where the median sits on either side by chance) keeps its value.

Weights: ``exp(−‖c_j − c_i‖₁ / sigma_color)`` (colour in [0, 1], L1 over the channels), times
``exp(−|p_j − p_i|² / 2 sigma_space²)`` when ``sigma_space`` is given, over a ``(2 radius + 1)²`` window.

Where it runs: float CPU tensors without gradient take the numba kernels of :mod:`~torch_depth_sr.edge_snap_kernel`
(several times faster, the same medians); other devices, autograd, other dtypes and ``TORCH_DEPTH_SR_NO_NUMBA`` the
torch code here (``_sided_median_torch``, ``_refit_torch``), the reference.
"""
from __future__ import annotations

from typing import Optional

import torch
import torch.nn.functional as F

from ._checks import check_4d, check_same_hw
from .native import host_kernel, host_path
from .window_max import max_filter, min_filter

__all__ = ["refit_to_measurements", "sided_median", "snap_to_sides"]

_PIXELS_PER_CHUNK = 16384  # edge pixels per gather in refit_to_measurements: 16384 × 121 × (8 + 3·8) bytes ≈ 63 MB
_SHARE_MARGIN = 1e-3  # snap_to_sides: below its share by this, a pixel cannot move (see there)
_ROWS_PER_CHUNK = 64  # bounds the (B, window, rows, W) stacks: 25 × 64 × 2000 × 8 bytes ≈ 26 MB at radius 2, float64


def _colour_weight(distance: torch.Tensor, sigma_color: float) -> torch.Tensor:
    """The colour weight of a neighbour at L1 colour ``distance`` (one kernel for both steps)."""
    return torch.exp(-distance / sigma_color)


def _weighted_median(values: torch.Tensor, weights: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Weighted median over the last dimension (the first value whose cumulative weight reaches half the total)
    and the total weight, both without that dimension."""
    sorted_values, order = values.sort(-1)
    cumulative = weights.gather(-1, order).cumsum(-1)
    total = cumulative[..., -1:]
    position = (cumulative < 0.5 * total).sum(-1, keepdim=True).clamp_max(values.shape[-1] - 1)
    return sorted_values.gather(-1, position)[..., 0], total[..., 0]


def sided_median(x: torch.Tensor, guide: torch.Tensor, radius: int = 2, sigma_color: float = 0.235,
                 sigma_space: Optional[float] = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Colour-weighted median of ``x`` in each window and the weight share on the median's side of ``x_i``.

    Args:
        x: (B,1,H,W) values (a depth estimate).
        guide: (B,C,H,W) colour in [0, 1] on the same grid.
        radius: window radius (the window is ``2 radius + 1`` square).
        sigma_color: colour scale of the weights (L1 distance over the channels).
        sigma_space: spatial Gaussian σ in pixels, or None for a flat window. Near the image border only the
            point-symmetric part of the window votes.

    Returns:
        ``(median, share)``, both (B,1,H,W): ``median`` is a value of ``x`` in the window (differentiable in
        ``x`` through the selection); ``share`` in [0, 1] is the weight of the window's values strictly on the
        median's side of ``x_i`` (below it when the median is below, above otherwise) over the total weight.

    Examples:
        >>> x = torch.tensor([[[[0., 0., 9., 10., 10.]]]]).expand(1, 1, 3, 5).contiguous()
        >>> rgb = torch.tensor([[[[0., 0., 1., 1., 1.]]]]).expand(1, 3, 3, 5).contiguous()
        >>> m, s = sided_median(x, rgb, radius=2)  # the 9 sits among white pixels that read 10
        >>> m[0, 0, 1].tolist(), round(float(s[0, 0, 1, 2]), 2)
        ([0.0, 0.0, 10.0, 10.0, 10.0], 0.67)
    """
    check_4d(x, "x", channels=1)
    check_4d(guide, "guide")
    check_same_hw(x, guide, "x", "guide")
    return _sided_median(x, guide, int(radius), sigma_color, sigma_space)


def _sided_median(x: torch.Tensor, guide: torch.Tensor, r: int, sigma_color: float, sigma_space: Optional[float],
                  cutoff: Optional[float] = None,
                  pixels: Optional[torch.Tensor] = None) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`sided_median`; with ``cutoff``, the numba kernel may report ``(x_i, 0)`` without sorting the window
    of a pixel whose share cannot exceed ``cutoff``, and with ``pixels`` (sorted flat indices into (B, H, W)) it
    computes only those (the torch path computes every pixel)."""
    spatial = None
    if sigma_space is not None:
        d = torch.arange(-r, r + 1, dtype=torch.float64, device=x.device)  # on the device: a CUDA graph captures it
        squared = (d[:, None] * d[:, None] + d[None, :] * d[None, :]).flatten()  # the offsets' order, row-major
        spatial = (-squared / (2.0 * sigma_space ** 2)).to(x.dtype).exp().view(1, -1, 1, 1)
    kernel = host_kernel("edge_snap_kernel", "sided_median_cpu", x, guide)
    if kernel is not None:
        return kernel(x, guide, r, sigma_color, spatial, cutoff, pixels)
    return _sided_median_torch(x, guide, r, sigma_color, spatial)


def _sided_median_torch(x: torch.Tensor, guide: torch.Tensor, r: int, sigma_color: float,
                        spatial: Optional[torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`sided_median` in torch (``spatial``: None or the window's offset weights, (1, n, 1, 1))."""
    b, _, h, w = x.shape
    offsets = [(dy, dx) for dy in range(-r, r + 1) for dx in range(-r, r + 1)]
    xp = F.pad(x, (r, r, r, r))
    # outside the image no vote; near the border the window is cut to its point-symmetric part (an offset votes
    # only if its mirror image is inside too), so that the median of a slanted plane stays the pixel's own value
    inside = F.pad(x.new_ones(1, 1, h, w), (r, r, r, r))
    gp = F.pad(guide.to(x), (r, r, r, r), mode="replicate")
    median, share = torch.empty_like(x), torch.empty_like(x)
    for r0 in range(0, h, _ROWS_PER_CHUNK):
        r1 = min(h, r0 + _ROWS_PER_CHUNK)
        rows = slice(r0 + r, r1 + r)
        centre_colour = gp[:, :, rows, r:r + w]
        values, weights = [], []
        for dy, dx in offsets:
            window_rows = slice(r0 + r + dy, r1 + r + dy)
            cols = slice(r + dx, r + dx + w)
            values.append(xp[:, 0, window_rows, cols])
            distance = (gp[:, :, window_rows, cols] - centre_colour).abs().sum(1)
            mirror_rows, mirror_cols = slice(r0 + r - dy, r1 + r - dy), slice(r - dx, r - dx + w)
            votes = inside[:, 0, window_rows, cols] * inside[:, 0, mirror_rows, mirror_cols]
            weights.append(_colour_weight(distance, sigma_color) * votes)
        # window last: the sort runs over contiguous memory (along a middle dimension it was ~3× slower)
        v, wt = torch.stack(values, -1), torch.stack(weights, -1)  # (B, rows, W, n)
        if spatial is not None:
            wt = wt * spatial.view(1, 1, 1, -1)
        m, total = _weighted_median(v, wt)
        xi = x[:, 0, r0:r1]
        below = (wt * (v < xi[..., None])).sum(-1)
        above = (wt * (v > xi[..., None])).sum(-1)
        median[:, 0, r0:r1] = m
        share[:, 0, r0:r1] = torch.where(m < xi, below, above) / total.clamp_min(torch.finfo(x.dtype).tiny)
    return median, share


def snap_to_sides(x: torch.Tensor, guide: torch.Tensor, rounds: int = 2, radius: int = 2, share: float = 0.6,
                  sigma_color: float = 0.235, sigma_space: Optional[float] = None,
                  active: Optional[torch.Tensor] = None, edge: Optional[float] = None) -> torch.Tensor:
    """``rounds`` passes of: ``x_i ← median_i`` where the :func:`sided_median` share exceeds ``share``.

    ``active`` (B,1,1,1) or (B,1,H,W) bool: where snapping may act (everywhere when None), e.g. the samples the
    singular test found outliers in. ``edge``: when given, snapping acts only where the ``5×5`` range of ``x``
    exceeds it (near a depth edge, in the units of ``x``, as :func:`refit_to_measurements`), and on the CPU only
    those windows are sorted; None: everywhere. Returns a new tensor; ``x`` is not modified.

    Examples:
        >>> x = torch.tensor([[[[0., 0., 5., 10., 10.]]]]).expand(1, 1, 3, 5).contiguous()  # a blend at 5
        >>> rgb = torch.tensor([[[[0., 0., 1., 1., 1.]]]]).expand(1, 3, 3, 5).contiguous()
        >>> snap_to_sides(x, rgb, rounds=1, radius=2)[0, 0, 1].tolist()
        [0.0, 0.0, 10.0, 10.0, 10.0]
    """
    if _no_sample_active(active, x):  # nothing may move: the result is x (no window of any sample is sorted)
        return x
    some = _some_samples_active(active, x)
    if some is not None:  # only the active samples' windows (each sample's result depends on its own only)
        g = guide if guide.shape[0] == 1 else guide[some]
        out = x.clone()
        out[some] = snap_to_sides(x[some], g, rounds, radius, share, sigma_color, sigma_space, edge=edge)
        return out
    check_4d(x, "x", channels=1)
    check_4d(guide, "guide")
    check_same_hw(x, guide, "x", "guide")
    # a pixel moves only where its share exceeds ``share``: the kernel skips the sort wherever the weight on each
    # side of x_i is at most ``share − _SHARE_MARGIN`` of the total (most pixels off an edge; the same result: the
    # margin is far above the round-off between its window-order sums and the share's sorted-order ones)
    cutoff = max(0.0, float(share) - _SHARE_MARGIN)
    b, _, h, w = x.shape
    for _ in range(int(rounds)):
        allowed, pixels = active, None
        if edge is not None:  # near a depth edge only
            near = _near_edge(x, edge)
            allowed = near if active is None else near & active
        if allowed is not None and allowed.shape[-2:] == (h, w) and host_path(x.device):
            pixels = _flat_pixels(allowed.expand(b, 1, h, w), h, w)  # on the CPU the other windows are not sorted
        median, side_share = _sided_median(x, guide, int(radius), sigma_color, sigma_space, cutoff, pixels)
        move = side_share > share
        if allowed is not None:
            move = move & allowed
        x = torch.where(move, median, x)
    return x


def _near_edge(x: torch.Tensor, edge: float) -> torch.Tensor:
    """Where the ``5×5`` range of ``x`` exceeds ``edge``: a depth edge is near (both edge steps' test)."""
    return (max_filter(x, 5) - min_filter(x, 5)) > edge


def _flat_pixels(where: torch.Tensor, h: int, w: int) -> torch.Tensor:
    """Flat indices into (B, H, W) of the pixels ``where`` is true, sorted ((B, 1 or C, H, W) bool, expanded)."""
    at = where.nonzero()
    return at[:, 0] * h * w + at[:, 2] * w + at[:, 3]


def _no_sample_active(active: Optional[torch.Tensor], x: torch.Tensor) -> bool:
    """Whether a per-sample ``active`` (B,1,1,1) says that no sample may change, checked on the CPU only: there
    reading it costs nothing, while on a GPU it would make the host wait for the device (the step then runs and
    changes nothing)."""
    if active is None or not host_path(x.device) or active.shape[-2:] != (1, 1):
        return False
    return not bool(active.any())


def _some_samples_active(active: Optional[torch.Tensor], x: torch.Tensor) -> Optional[torch.Tensor]:
    """The indices of the active samples when a per-sample ``active`` leaves some out (CPU only, as above), else
    None."""
    if active is None or not host_path(x.device) or active.shape[-2:] != (1, 1) or active.shape[0] != x.shape[0]:
        return None
    a = active.reshape(-1)
    return None if bool(a.all()) else a.nonzero()[:, 0]


def refit_to_measurements(x: torch.Tensor, y: torch.Tensor, observed: torch.Tensor, guide: torch.Tensor,
                          radius: int = 5, band: float = 1.5, edge: float = 2.0, sigma_color: float = 0.235,
                          active: Optional[torch.Tensor] = None) -> torch.Tensor:
    """Near depth edges, ``x_i ←`` the colour-weighted median of the *measurements* ``y_j`` within ``band`` of ``x_i``.

    A restorer's values next to a depth edge are pulled towards the other surface (its smoothing reaches across);
    the measurements of the pixel's own side are not, and the median of those within ``band`` of ``x_i`` (which
    excludes the other surface, flying pixels and impulses) is an estimate of the side's value free of that pull.
    It acts where the ``5×5`` range of ``x`` exceeds ``edge`` (a depth edge is near) and at least one full colour
    weight votes; elsewhere ``x`` is kept. ``band`` and ``edge`` are in the units of ``x`` (the model passes noise-σ
    units). Weights as :func:`sided_median`, over a ``(2 radius + 1)²`` window of measured pixels.

    Examples:
        >>> y = torch.tensor([[[[10., 11., 9., 10., 50., 51., 49.]]]]).expand(1, 1, 3, 7).contiguous()
        >>> x = y.clone(); x[..., 3] = 14.0  # a value next to the edge, pulled towards the far side
        >>> rgb = torch.zeros(1, 3, 3, 7); rgb[:, :, :, 4:] = 1.0
        >>> refit_to_measurements(x, y, torch.ones_like(y), rgb, radius=3, band=5.0, edge=20.0)[0, 0, 1, 3].item()
        10.0
    """
    check_4d(x, "x", channels=1)
    check_same_hw(x, y, "x", "y")
    check_same_hw(x, guide, "x", "guide")
    if _no_sample_active(active, x):  # nothing may change: the result is x
        return x
    b, _, h, w = x.shape
    r = int(radius)
    near_edge = _near_edge(x, edge)
    if active is not None:
        near_edge = near_edge & active
    cpu = host_path(x.device)
    # the pixels near an edge: on the CPU a gather over 2–5 % of the pixels instead of a sort over all. Other devices
    # take every pixel (finding them would make the host wait for the device) and keep the result near an edge only:
    # the same values.
    pixels = _flat_pixels(near_edge, h, w) if cpu else None
    if cpu and pixels.shape[0] == 0:
        return x
    kernel = host_kernel("edge_snap_kernel", "refit_cpu", x, y, guide)
    if kernel is not None:
        return kernel(x, y, observed, guide, pixels, r, band, sigma_color)
    return _refit_torch(x, y, observed, guide, near_edge, pixels, r, band, sigma_color)


def _refit_torch(x: torch.Tensor, y: torch.Tensor, observed: torch.Tensor, guide: torch.Tensor,
                 near_edge: torch.Tensor, pixels: Optional[torch.Tensor], r: int, band: float,
                 sigma_color: float) -> torch.Tensor:
    """:func:`refit_to_measurements` in torch at ``pixels`` (flat indices into (B, H, W); None = every pixel, the
    result kept where ``near_edge``)."""
    b, _, h, w = x.shape
    cpu = pixels is not None
    yp = F.pad(torch.where(observed > 0, y, torch.zeros_like(y)), (r, r, r, r)).reshape(-1)
    op = F.pad((observed > 0).to(x.dtype), (r, r, r, r)).reshape(-1)
    gp = F.pad(guide.to(x), (r, r, r, r), mode="replicate")
    # the padded planes read by one flat index per window pixel (the same values as indexing by sample, row and
    # column, several times faster); the colour with its channels last, one row per padded pixel
    hp, wp = h + 2 * r, w + 2 * r
    colour_rows = gp.expand(b, -1, hp, wp).permute(0, 2, 3, 1).reshape(b * hp * wp, -1)
    d = torch.arange(-r, r + 1, device=x.device)  # on the device, not copied from the host (a CUDA graph captures it)
    offsets = (d[:, None] * wp + d[None, :]).flatten()  # dy * wp + dx, row-major
    out = x.clone(memory_format=torch.contiguous_format)
    flat_out, flat_x = out.view(-1), x.reshape(-1)
    if pixels is None:
        pixels = torch.arange(b * h * w, device=x.device)
    flat_near = near_edge.expand(b, 1, h, w).reshape(-1)
    for start in range(0, pixels.shape[0], _PIXELS_PER_CHUNK):
        flat = pixels[start:start + _PIXELS_PER_CHUNK]
        bi, ri, ci = flat // (h * w), flat // w % h, flat % w
        centre_index = (bi * hp + ri + r) * wp + ci + r  # (n,) in the padded frame
        window = centre_index[:, None] + offsets[None, :]  # (n, window)
        values, votes = yp[window], op[window]
        out_index = (bi * h + ri) * w + ci
        centre = flat_x[out_index][:, None]
        distance = (colour_rows[window] - colour_rows[centre_index][:, None, :]).abs().sum(-1)  # (n, window)
        weight = _colour_weight(distance, sigma_color) * votes * ((values - centre).abs() <= band)
        median, total = _weighted_median(values, weight)
        new = torch.where(total > 1.0, median, centre[:, 0])
        flat_out[out_index] = new if cpu else torch.where(flat_near[out_index], new, centre[:, 0])
    return out
