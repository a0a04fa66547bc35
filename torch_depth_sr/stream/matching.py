"""Block matching in a stream: the previous frame's matches where the scene has not changed, a search elsewhere.

A pixel whose whole search window (and the blocks around the candidates) is static sees the same blocks as in the
previous frame, so its matches are still the best ones: :class:`StreamMatcher` keeps them (their distances, with
the weights recomputed at the model's current temperature, so that the temperature still learns). The other pixels
are searched as the model searches them (the exact search for x⁰, the model's re-matching in its scheduled layers).
On the CPU, x⁰'s search runs at those pixels alone, inside the whole image
(:func:`~torch_depth_sr.block_matching.block_match_at`). Otherwise it runs on rectangles around them: each is padded
by the search radius plus the block radius, so that every candidate block of its core lies inside it. Each rectangle
starts on a row that is a multiple of the block size, so that the CPU kernel's block sums add the rows in the whole
image's order. Either way a searched pixel's matches are the whole image's, to the last bit.

The rectangles had cost most of a moving step's search: at 640×480 they covered about 30 % of the frame for 10 %
fresh pixels, and a narrow one paid the kernel's cost per row for a few columns
(docs/measurements/issue28-stream/twenty-ninth-stop/).
"""
from __future__ import annotations

from dataclasses import replace
from typing import Optional

import torch

from ..block_matching import BlockMatches
from ..block_matching._common import candidates_everywhere, finish
from ..config import BlockMatchingConfig
from ..native import host_kernel
from ..observation import Observation
from ..stages import BlockMatcher

__all__ = ["StreamMatcher", "crop_matches", "crops", "search_radius"]


def search_radius(settings: BlockMatchingConfig, task: str) -> int:
    """The reach of a pixel's matches in pixels: the search radius plus the block radius."""
    window, _ = settings.window_and_k()[task]
    return window // 2 + settings.block_size // 2


def _runs(flags: torch.Tensor, pad: int, size: int, align: int = 1) -> list[tuple[int, int, int, int]]:
    """Runs ``(a, b, c0, c1)`` covering the ``True`` entries of ``flags (N,)``: the crop ``[a, b)`` (the run padded by
    ``pad``, clipped to ``[0, size)``, ``a`` a multiple of ``align``) and its core ``[c0, c1)``. Runs whose crops
    would overlap are merged."""
    runs: list[list[int]] = []
    for i in torch.nonzero(flags).flatten().tolist():
        if runs and i <= runs[-1][1] + 2 * pad + align:
            runs[-1][1] = i
        else:
            runs.append([i, i])
    return [(max(0, c0 - pad) // align * align, min(size, c1 + 1 + pad), c0, c1 + 1) for c0, c1 in runs]


def crops(fresh: torch.Tensor, pad: int, align: int = 1) -> list[tuple[slice, slice, slice, slice]]:
    """Rectangles that cover the ``True`` pixels of ``fresh (B,1,H,W)`` (over the batch): bands of rows, and in each
    band runs of columns, each padded by ``pad`` (clipped to the image). Returns ``(rows, cols, core_rows,
    core_cols)``: the crop and the part of it whose matches the crop gives exactly (every candidate block of a core
    pixel lies in the crop). ``align``: the crops' first rows are multiples of it (the block size: the CPU kernel's
    block sums then add a crop's rows in the whole image's order, to the last bit)."""
    h, w = fresh.shape[-2:]
    any_b = fresh.flatten(0, 1).any(0)  # (H, W)
    out = []
    for a, b, r0, r1 in _runs(any_b.any(1), pad, h, align):
        for c, d, q0, q1 in _runs(any_b[r0:r1].any(0), pad, w):
            out.append((slice(a, b), slice(c, d), slice(r0, r1), slice(q0, q1)))
    return out


def crop_matches(m: BlockMatches, rows: slice, cols: slice, width: int, outside: str = "missing") -> BlockMatches:
    """Matches of a crop with their flat indices in the crop's frame. A match outside the crop is ``"missing"``
    (index -1: re-matching replaces it) or its pixel's ``"own"`` index with no weight (for the layers, which read
    every index)."""
    kernel = host_kernel("stream.matches_kernel", "crop_matches_cpu", m.weight)
    if kernel is not None and m.index.dtype == torch.int64:
        index, weight = kernel(m.index, m.weight, rows, cols, width, outside == "own")
        return BlockMatches(m.dist[..., rows, cols], index, weight)
    index = m.index[..., rows, cols]
    # the row and column in int32 where the flat indices fit: int64 division took half of this function's time
    flat = index.to(torch.int32) if width * (m.index.shape[-2] + 1) < 2**31 else index
    y = torch.div(flat, width, rounding_mode="floor")
    x = flat - y * width - cols.start
    y = y - rows.start
    wc, hc = cols.stop - cols.start, rows.stop - rows.start
    inside = (y >= 0) & (y < hc) & (x >= 0) & (x < wc)
    moved = (y * wc + x).to(index.dtype)
    weight = m.weight[..., rows, cols]
    if outside == "own":
        own = torch.arange(hc * wc, device=index.device, dtype=index.dtype).view(hc, wc).expand_as(index)
        return BlockMatches(m.dist[..., rows, cols], torch.where(inside, moved, own),
                            torch.where(inside, weight, torch.zeros_like(weight)))
    return BlockMatches(m.dist[..., rows, cols], torch.where(inside, moved, torch.full_like(index, -1)), weight)


class StreamMatcher:
    """The model's :class:`~torch_depth_sr.stages.BlockMatcher` (``inner``) for one stream frame: the matches
    ``previous`` (the previous frame's last, ``(dist, index)`` without gradient) are kept where ``fresh`` (B,1,H,W)
    is False; the pixels where it is True are searched by ``inner`` (module docstring). It stands where the model's
    matcher stands (``obs.block_matcher``): x⁰'s matches (a call) and a scheduled layer's (:meth:`rematch`).
    ``weights``: the previous matches' softmax weights and the temperature they were made at, kept where nothing is
    searched when the temperature is the same and no gradient is wanted. The first call writes into ``previous``
    (and ``weights``); later calls into copies."""

    def __init__(self, inner: BlockMatcher, previous: tuple[torch.Tensor, torch.Tensor], fresh: torch.Tensor,
                 weights: Optional[tuple[torch.Tensor, torch.Tensor]] = None):
        self.inner = inner
        self.previous_dist, self.previous_index = previous
        self.fresh = fresh
        # the previous matches' weights and the temperature they were made at: with nothing fresh, the same
        # temperature and no gradient wanted, the softmax would give them again bit for bit
        self.previous_weights = weights
        self._owned = True  # the kept lists may be written in place (the frame's first call)
        self.searched = 0  # pixels searched (crops included), summed over the calls of this frame

    # the matcher's interface as the model's stages read it
    @property
    def settings(self) -> BlockMatchingConfig:
        return self.inner.settings

    @property
    def temperature(self) -> torch.Tensor:
        return self.inner.temperature

    @property
    def color_weight(self) -> torch.Tensor:
        return self.inner.color_weight

    def scheduled(self, index: int) -> bool:
        return self.inner.scheduled(index)

    def __call__(self, x: torch.Tensor, obs: Observation, q: torch.Tensor) -> BlockMatches:
        """x⁰'s matches: the kept ones, and the exact search where fresh."""
        return self._mix(x, obs, q, None)

    def rematch(self, x: torch.Tensor, obs: Observation, q: torch.Tensor, previous: BlockMatches) -> BlockMatches:
        """A scheduled layer's matches: the kept ones, and the model's re-matching from ``previous`` where fresh."""
        return self._mix(x, obs, q, previous)

    def _search(self, x, obs, q, previous) -> BlockMatches:
        if previous is None:
            return self.inner(x, obs, q)
        return self.inner.rematch(x, obs, q, previous)

    def _mix(self, x: torch.Tensor, obs: Observation, q: torch.Tensor,
             previous: Optional[BlockMatches]) -> BlockMatches:
        dist, index = self.previous_dist.to(x.dtype), self.previous_index
        weights = self.previous_weights[0] if self._weights_hold(dist) else None
        if not bool(self.fresh.any()):
            if weights is None:
                return finish(dist.detach(), index, self.temperature)
            return BlockMatches(dist, index, weights)
        # the frame's first call writes into the kept lists (the previous frame needs them no more: a whole frame's
        # copy of k planes cost more than its search of the fresh pixels at 1.5 MP); a later one (a re-matching layer)
        # into a copy, so that the matches an earlier call returned stay as they were
        if not self._owned:
            dist, index = dist.clone(), index.clone()
            weights = None if weights is None else weights.clone()
        self._owned = False
        if previous is not None or not self._search_fresh(x, obs, q, dist, index):
            self._search_crops(x, obs, q, previous, dist, index)
        return self._finish(dist, index, weights)

    def _search_crops(self, x: torch.Tensor, obs: Observation, q: torch.Tensor, previous: Optional[BlockMatches],
                      dist: torch.Tensor, index: torch.Tensor) -> None:
        """The fresh pixels' matches searched by ``inner`` on crops around them, pasted into ``dist`` and ``index``."""
        h, w = x.shape[-2:]
        s = self.settings
        window, k = s.window_and_k()[obs.task]
        k_full = min(k, candidates_everywhere(h, w, window, s.include_self))
        boxes = crops(self.fresh, search_radius(s, obs.task), align=s.block_size)
        area = sum((r.stop - r.start) * (c.stop - c.start) for r, c, _, _ in boxes)
        thin = any(min(k, candidates_everywhere(r.stop - r.start, c.stop - c.start, window, s.include_self))
                   != k_full for r, c, _, _ in boxes)
        if area >= 0.8 * h * w or thin:  # nearly everything, or a crop too small for k candidates: whole image
            full = slice(0, h), slice(0, w)
            boxes = [(*full, *full)]
        q_full = q if q.shape[-2:] == (h, w) else None
        for rows, cols, core_r, core_c in boxes:
            crop_obs = replace(obs, rgb=None if obs.rgb is None else obs.rgb[..., rows, cols])
            crop_q = q_full[..., rows, cols] if q_full is not None else q
            prev = None if previous is None else crop_matches(previous, rows, cols, w)
            m = self._search(x[..., rows, cols], crop_obs, crop_q, prev)
            self.searched += (rows.stop - rows.start) * (cols.stop - cols.start)
            wc = cols.stop - cols.start
            inner = (slice(core_r.start - rows.start, core_r.stop - rows.start),
                     slice(core_c.start - cols.start, core_c.stop - cols.start))
            found = m.index[..., inner[0], inner[1]]
            found = (found // wc + rows.start) * w + found % wc + cols.start  # back to the whole image
            fresh = self.fresh[..., core_r, core_c]
            dist[..., core_r, core_c] = torch.where(fresh, m.dist[..., inner[0], inner[1]].to(dist.dtype),
                                                    dist[..., core_r, core_c])
            index[..., core_r, core_c] = torch.where(fresh, found, index[..., core_r, core_c])

    def _search_fresh(self, x: torch.Tensor, obs: Observation, q: torch.Tensor, dist: torch.Tensor,
                      index: torch.Tensor) -> bool:
        """x⁰'s exact search at the fresh pixels alone, into ``dist`` and ``index`` (the whole image's matches
        there; on the CPU's kernel, :meth:`BlockMatcher.search_at`), not the crops, which search their padding and
        the gaps between the fresh pixels too. False where it does not run."""
        if not self.inner.search_at(x, obs, q, self.fresh, dist, index):
            return False
        self.searched += int(self.fresh.sum())
        return True

    def _finish(self, dist: torch.Tensor, index: torch.Tensor, weights: Optional[torch.Tensor]) -> BlockMatches:
        """The matches with their weights: the kept ones where nothing was searched (when they hold), the softmax
        of the fresh pixels' lists there (it is per pixel: the whole frame's, to the last bit of torch's vectorised
        exp, which the layout can change); without kept weights the softmax everywhere, at the current temperature
        (it learns)."""
        if weights is None:
            return finish(dist.detach(), index, self.temperature)
        at = self.fresh[:, 0]  # (B, H, W): the fresh pixels' lists as rows (N, k)
        lists = dist.permute(0, 2, 3, 1)[at].T[None, ..., None]  # (1, k, N, 1)
        # finish's softmax over k (its index argument is only passed through)
        weights.permute(0, 2, 3, 1)[at] = finish(lists, lists, self.temperature).weight[0, ..., 0].T
        return BlockMatches(dist.detach(), index, weights)

    def _weights_hold(self, dist: torch.Tensor) -> bool:
        """Whether the previous weights are what :func:`finish` would give for ``dist`` now."""
        if self.previous_weights is None:
            return False
        weight, made_at = self.previous_weights
        t = self.temperature
        if t.requires_grad and torch.is_grad_enabled():  # the weights must carry the temperature's gradient
            return False
        return (weight.dtype == dist.dtype and weight.shape == dist.shape
                and torch.equal(made_at, t.detach().to(made_at)))
