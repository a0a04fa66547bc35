"""A mover's trail in a stream (issue 28, ``docs/stream.md#other-scenes-of-the-same-recipes``): what the stream
does against it. A limit the stream has today is written here as ``xfail(strict=True)``: it turns into a failure of
the suite when the stream learns it, so that this file and the docs are brought up to date (one at present: a
sliding slanted surface, ``docs/stream.md#where-it-stops``)."""
from __future__ import annotations

from dataclasses import replace
from typing import Optional

import numpy as np
import pytest
import torch

from torch_depth_sr import StreamRestorer, restore_depth
from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, make_sequence
from torch_depth_sr.evaluation.stream import regions, synthetic_metrics
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
    # mover's new measurements join the background's running mean (446 pixels over 12 frames, 243 with it, when
    # written; 509 and 238 at the thirty-first stop), both without the shift test and the drift test, which came
    # after and find much of this mover on their own
    (unbounded,) = _far_off(202, 12, {"join_cap": None, "shift_test": None, "drift_test": None}, frame_by_frame=False)
    (bounded,) = _far_off(202, 12, {"shift_test": None, "drift_test": None}, frame_by_frame=False)
    assert bounded < 0.7 * unbounded, (bounded, unbounded)


def test_the_shift_test_keeps_a_slow_mover_where_it_is_measured():
    # the same scene over 26 frames: without the shift test the mover's edge pixels left their runs a frame late,
    # every frame (held out, or dropped as outliers in time), and 522 well-measured pixels came out more than 100 mm
    # off, against 241 frame by frame; with it 164 (the twentieth stop; 1255 before join_cap)
    stream, frame = _far_off(202, 26)
    (without,) = _far_off(202, 26, {"shift_test": None}, frame_by_frame=False)
    assert stream <= frame < without, (stream, frame, without)


def test_the_trail_of_the_evaluated_static_busy_sequence_is_no_longer_than_frame_by_frame():
    # until the twenty-sixth stop 1.0 % longer (118.32 against 117.11): flying pixels at the movers that the stream's
    # singular test trusted and frame-by-frame's did not. The stream no longer trusts a measurement of this frame alone
    # that no neighbour agrees with (StreamConfig.single_support, chosen on the fitting sequences, not on this one)
    seq = make_sequence(STREAM_SEQUENCES[2], frames=30, height=120, width=160)
    model, reg = default_stream_model(), regions(seq)
    stream = StreamRestorer(model)
    with torch.no_grad():
        outs = [np.stack([np.asarray(step(seq["depth"][t, 0], torch.from_numpy(seq["rgb"][t])), dtype=np.float32)
                          for t in range(30)])
                for step in (stream.step, lambda d, c: restore_depth(d, c, model=model))]
    trail = [synthetic_metrics(out, seq, reg)["trail"] for out in outs]
    assert trail[0] <= trail[1], trail


def _sliding_plane(frames=16, h=48, w=64, seed=1):
    """A plane whose depth rises 3 mm a column, sliding right by a pixel a frame (a slanted face of a moving object:
    each pixel's depth falls 3 mm a frame, within one pixel of where it was), grey, with 2 mm noise."""
    rng = np.random.default_rng(seed)
    xx = np.arange(w, dtype=np.float64)[None, :].repeat(h, 0)
    truth = [1500.0 + 3.0 * (xx - t) for t in range(frames)]
    depth = [np.round(z + 2.0 * rng.standard_normal(z.shape)).astype(np.float32) for z in truth]
    return depth, truth, np.full((h, w, 3), 0.5, np.float32)


def _lag(outs, truth) -> float:
    """The mean of output − truth over the last 8 frames, 4 px from the border (mm)."""
    return float(np.mean([np.mean(np.asarray(o)[4:-4, 4:-4] - t[4:-4, 4:-4]) for o, t in zip(outs[-8:], truth[-8:])]))


@pytest.mark.xfail(strict=True, reason="the change test passes an untextured slanted surface sliding a pixel a frame "
                   "(the depth test's one-pixel tolerance; the drift test needs the colour to change) and the runs' "
                   "means lag it (docs/stream.md#where-it-stops)")
def test_a_sliding_slanted_grey_plane_is_not_left_behind():
    # frame by frame follows the plane (within 0.05 mm on the mean); the stream lags it by 16 mm on the mean of the
    # last 8 frames (19 mm in the last: more than six frames' fall), since each frame's change at a pixel, 3 mm,
    # lies within the depth test's one-pixel tolerance. The drift test sees the depth drift but counts it only where
    # the colour changed too (a real sensor's depth drifts on a still scene: docs/measurements/issue28-stream/
    # thirty-first-stop/), and a grey plane's colour does not; a textured one is followed (test_stream_drift.py)
    depth, truth, rgb = _sliding_plane()
    model = default_stream_model()
    with torch.no_grad():
        frame = [restore_depth(d, rgb, model=model) for d in depth[-8:]]
        stream = StreamRestorer(model)
        outs = [stream.step(d, rgb) for d in depth]
    assert abs(_lag(frame, truth)) < 0.5
    assert abs(_lag(outs, truth)) < 1.0, _lag(outs, truth)
