"""α⁰ of a stream frame with the previous frame's values where the scene stayed: :class:`WarmStart`.

α⁰, the nonlocal mean of x⁰'s gradients over each pixel's matches, is a pass over the whole frame that no other
stream state replaced (about 11 ms of a 0.15 s ``fast`` step at 640×480). At a static pixel whose run has its full
mean (``max_frames`` measurements) it reads nearly what the previous frame read: the same matches (kept by
:class:`~torch_depth_sr.stream.matching.StreamMatcher`) and means that one new measurement moves by a ninth of its
noise. There :class:`WarmStart` keeps the previous frame's α⁰ (itself possibly kept from earlier frames, while the
run lasts). At the other pixels, *fresh* (changed, or a young run: where the later layers run,
:mod:`~torch_depth_sr.stream.crop_layers`), and at every pixel whose matches reach a fresh one, it computes α⁰ on
crops padded by that reach, and on the whole frame when the crops would cover most of it.

x⁰'s colour-guided fill is not kept this way: tried, a fill one frame old at the holes raised the flicker of the
stream track's ``static-busy`` sequence by 12 % (``docs/stream.md``).
"""
from __future__ import annotations

from typing import Optional

import torch

from ..initial import ColdStart
from .matching import crop_matches, crops, dilate

__all__ = ["WarmStart"]

WHOLE_FRAME_SHARE = 0.8  # crops covering this share of the frame or more: the whole frame instead (as crop_layers)


class WarmStart(ColdStart):
    """α⁰ of one stream frame: ``previous`` (the previous frame's, or None) kept where ``fresh`` (B,1,H,W) bool is
    False and no match reaches a fresh pixel, computed on crops elsewhere; ``fresh`` None: on the whole frame.
    ``reach`` is the reach of a pixel's matches (:func:`~torch_depth_sr.stream.matching.search_radius`). What this
    frame computed or kept is :attr:`kept`, and :attr:`computed` the share of the frame it computed."""

    def __init__(self, previous: Optional[torch.Tensor], fresh: Optional[torch.Tensor], reach: int):
        self.previous, self.fresh, self.reach = previous, fresh, reach
        self.kept: Optional[torch.Tensor] = None
        self.computed = 1.0

    def alpha(self, compute, x0: torch.Tensor, matches) -> torch.Tensor:
        out = self._alpha(compute, x0, matches)
        self.kept = out.detach()
        return out

    def _alpha(self, compute, x0: torch.Tensor, matches) -> torch.Tensor:
        previous, fresh = self.previous, self.fresh
        if previous is None or fresh is None or previous.shape[-2:] != x0.shape[-2:]:
            return compute(x0, matches)
        h, w = x0.shape[-2:]
        pad = self.reach + 1  # a pixel's matches and the forward difference at each
        fresh = dilate(fresh, pad)  # every pixel that reads a fresh one
        boxes = crops(fresh, pad) if bool(fresh.any()) else []
        area = sum((r.stop - r.start) * (c.stop - c.start) for r, c, _, _ in boxes)
        if area >= WHOLE_FRAME_SHARE * h * w:
            return compute(x0, matches)
        self.computed = area / (h * w)
        out = previous.to(x0)
        if boxes:
            out = out.clone()
        for rows, cols, core_r, core_c in boxes:
            part = compute(x0[..., rows, cols], None if matches is None else
                           crop_matches(matches, rows, cols, w, outside="own"))
            inner = (slice(core_r.start - rows.start, core_r.stop - rows.start),
                     slice(core_c.start - cols.start, core_c.stop - cols.start))
            out[..., core_r, core_c] = torch.where(fresh[..., core_r, core_c], part[..., inner[0], inner[1]],
                                                   out[..., core_r, core_c])
        return out
