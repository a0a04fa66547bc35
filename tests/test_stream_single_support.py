"""The stream's rule for its single measurements (``StreamConfig.single_support``): a measurement of this frame alone
(not a run's mean) without agreeing neighbours is not trusted, whatever the singular test says. A flying pixel at a
mover floats alone (issue 28, docs/measurements/issue28-stream/twenty-sixth-stop/)."""
from __future__ import annotations

import numpy as np
import pytest
import torch

import torch_depth_sr.stages as stages
from torch_depth_sr import DepthRestorer, StreamRestorer
from torch_depth_sr.config import StreamConfig
from torch_depth_sr.errors import DepthSRError

H, W = 40, 48


def _model() -> DepthRestorer:
    return DepthRestorer(num_layers=3, block_matching={"search_window": 7, "k": 6, "match_layers": (1,)})


def _frames():
    """A still slanted plane (mm), then a near object arriving at rows 10-19, columns 8-19, with a flying pixel
    halfway between it and the plane just left of its edge."""
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    gt = 1500 + 2 * yy + xx
    rgb = np.zeros((H, W, 3), np.float32)
    rgb[...] = [0.2, 0.4, 0.8]
    first = np.round(gt + 4 * rng.standard_normal(gt.shape)).astype(np.uint16)
    moved, colour = gt.copy(), rgb.copy()
    moved[10:20, 8:20] = 700
    colour[10:20, 8:20] = [0.9, 0.2, 0.1]
    second = np.round(moved + 4 * rng.standard_normal(gt.shape)).astype(np.uint16)
    second[15, 7] = 1100  # flying pixel beside the arrival: between 700 and ~1550
    return (first, rgb), (second, colour)


def _run(settings=None, seen=None):
    """The second frame's details; ``seen`` (a list) is emptied after the first frame."""
    s = StreamRestorer(_model(), settings)
    first, second = _frames()
    s.step(*first)
    if seen is not None:
        seen.clear()
    return s.step(*second, return_details=True)


@pytest.fixture
def detector_sees(monkeypatch) -> list:
    """What each singular test is given: ``(untrusted, gate_region, supported)``, or None without the rule."""
    seen = []
    forward = stages.SingularDetector.forward

    def spy(self, obs, x, matches, held=None):
        u = obs.untrusted
        seen.append(None if u is None else (u.clone(), obs.gate_region.clone(), obs.supported.clone()))
        return forward(self, obs, x, matches, held)

    monkeypatch.setattr(stages.SingularDetector, "forward", spy)
    return seen


def test_an_unsupported_measurement_of_this_frame_alone_is_not_trusted(detector_sees):
    seen = detector_sees
    r = _run(seen=seen)
    assert seen and all(c is not None and torch.equal(c[0], seen[-1][0]) for c in seen)  # x⁰'s test, every layer's
    untrusted, alone, supported = (t[0, 0] for t in seen[-1])
    assert bool(untrusted[15, 7])  # the flying pixel beside the arrival: no neighbour agrees with it
    assert not bool(np.asarray(r.trusted)[15, 7])
    assert not bool((untrusted & ~alone).any())  # a run's mean: the singular test alone decides
    assert not bool((untrusted & supported).any())  # the model's own support (3 neighbours) is support
    # the arrival, measured afresh: its noise (σ 4 mm) leaves a pixel alone only in its tail
    assert float(untrusted[11:19, 9:19].float().mean()) < 0.05
    assert float(np.asarray(r.trusted)[11:19, 9:19].mean()) > 0.9


def test_without_the_rule_nothing_is_marked(detector_sees):
    _run({"single_support": None}, seen=detector_sees)
    assert detector_sees and all(c is None for c in detector_sees)


def test_the_rule_changes_only_the_trust_of_the_marked_pixels():
    """Where the rule marks nothing, the verdicts are the singular test's: the two streams trust the same pixels
    everywhere but at the marked ones (and the pixels their changed estimate moves the test of, near them)."""
    on, off = _run(), _run({"single_support": None})
    t_on, t_off = np.asarray(on.trusted) > 0, np.asarray(off.trusted) > 0
    differ = t_on != t_off
    assert differ[15, 7] or not t_off[15, 7]
    assert differ.mean() < 0.02


def test_the_count_is_checked():
    with pytest.raises(DepthSRError, match="single_support"):
        StreamConfig(single_support=0)
    assert StreamConfig(single_support=None).single_support is None
    assert StreamConfig().single_support == 1
