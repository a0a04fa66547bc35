"""A slow mover's trail in a stream (issue 28, ``docs/stream.md#other-scenes-of-the-same-recipes``): what the stream
does against it, and, as tests that fail today (``xfail(strict=True)``), what it does not do yet: each of those turns
into a failure of the suite when the stream learns it, so that this file and the docs are brought up to date."""
from __future__ import annotations

from dataclasses import replace
from typing import Optional

import numpy as np
import pytest
import torch

from torch_depth_sr import StreamRestorer, restore_depth
from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, make_sequence
from torch_depth_sr.stream import default_stream_model


def _far_off(seed: int, frames: int, settings: Optional[dict] = None, frame_by_frame: bool = True) -> list:
    """Pixels the sensor measured within 10 mm of the truth that come out more than 100 mm off, summed over the
    frames of the ``static-2movers`` recipe with ``seed``: [stream with ``settings``, frame by frame (if asked)]."""
    spec = replace(STREAM_SEQUENCES[0], name=f"static-2movers@{seed}", seed=seed)
    seq = make_sequence(spec, frames=frames, height=120, width=160)
    model = default_stream_model()
    stream = StreamRestorer(model, settings)
    counts = [0, 0] if frame_by_frame else [0]
    with torch.no_grad():
        for t in range(frames):
            depth, rgb, gt = seq["depth"][t, 0], torch.from_numpy(seq["rgb"][t]), seq["gt"][t, 0]
            good = (depth > 0) & (np.abs(depth - gt) < 10)
            outs = [stream.step(depth, rgb)] + ([restore_depth(depth, rgb, model=model)] if frame_by_frame else [])
            for i, out in enumerate(outs):
                counts[i] += int((np.abs(np.asarray(out, dtype=np.float64) - gt)[good] > 100).sum())
    return counts


def test_join_cap_keeps_a_slow_mover_nearer_its_measurements():
    # static-2movers@202: a mover at 0.52 m advancing 1–2 px per frame over a background at 1.36 m; the change test's
    # noise unit grows to 0.3–0.5 m by the edge. Without the bound on the unit the run's mean is compared in, the
    # mover's new measurements join the background's running mean (446 pixels over 12 frames; 243 with it)
    (unbounded,) = _far_off(202, 12, {"join_cap": None}, frame_by_frame=False)
    (bounded,) = _far_off(202, 12, frame_by_frame=False)
    assert bounded < 0.7 * unbounded, (bounded, unbounded)


@pytest.mark.xfail(strict=True, reason="issue 28: a slow mover of nearly the background's colour leaves a trail "
                                       "(docs/stream.md#other-scenes-of-the-same-recipes)")
def test_a_slow_mover_is_not_pushed_behind_its_measurements():
    # the same scene over 26 frames: 1255 well-measured pixels more than 100 mm off without join_cap, 522 with it,
    # 241 frame by frame (the leading edge, held out or dropped for a frame, still lags)
    stream, frame = _far_off(202, 26)
    assert stream <= frame, f"{stream} well-measured pixels more than 100 mm off in the stream, {frame} frame by frame"
