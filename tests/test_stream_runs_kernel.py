"""The stream's run updates: the numba kernels (stream/runs_kernel.py) give the torch path's maps bit for bit, on
inputs that reach every branch (outliers in time, confirmed and held-out departures, holes with and without
evidence, young and full runs)."""
import pytest
import torch

from torch_depth_sr.config import StreamConfig
from torch_depth_sr.stream import runs


def _inputs(shape, dtype, seed):
    g = torch.Generator().manual_seed(seed)

    def r(*a):
        return torch.rand(shape, generator=g, dtype=dtype)

    offset = 500 + 100 * torch.rand(shape[0], generator=g, dtype=dtype)
    scale = 20 + 10 * torch.rand(shape[0], generator=g, dtype=dtype)
    depth = 400 + 300 * r()
    y = (depth - offset.view(-1, 1, 1, 1)) / scale.view(-1, 1, 1, 1)
    observed = (r() > 0.2).to(dtype)
    y = y * observed
    static = r() > 0.3
    candidate = r() > 0.8
    noise = 0.05 + 0.3 * r()
    evidence = torch.where(r() > 0.3, torch.floor(9 * r()), 0.4 * r())  # whole counts, and decayed ones below 1
    mean = torch.where(r() > 0.2, depth + 40 * (r() - 0.5), torch.zeros_like(depth))  # near y, far, or none
    departed = torch.where(r() > 0.7, depth + 2 * (r() - 0.5), torch.zeros_like(depth))  # some confirm y
    age = torch.floor(10 * r())
    return y, observed, static, candidate, noise, evidence, mean, departed, age, offset, scale


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("shape", [(1, 1, 1, 1), (1, 1, 3, 5), (2, 1, 37, 70)])
@pytest.mark.parametrize("settings", [StreamConfig(), StreamConfig(outlier_test=None, weight=0.3, hole_decay=0.7),
                                      StreamConfig(settled_frames=3, unmeasured_frames=2.0)])
def test_join_and_grow_kernels_equal_torch(monkeypatch, dtype, shape, settings):
    args = _inputs(shape, dtype, sum(shape))
    joined = runs.join_runs(*args, settings)
    y, observed, static, _, _, evidence, mean, _, age, offset, scale = args
    g = torch.Generator().manual_seed(7)
    trusted = (observed > 0) & (torch.rand(shape, generator=g) > 0.1)
    conf = torch.rand(shape, generator=g, dtype=dtype) * observed
    past_conf = torch.rand(shape, generator=g, dtype=dtype)
    grow = (joined.y, joined.observed, trusted, conf, static, joined.restarted, evidence, age, past_conf, mean, offset,
            scale, settings)
    grown = runs.grow_runs(*grow)
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    ref = runs.join_runs(*args, settings)
    for name, a, b in zip(runs.JoinedRuns._fields, joined, ref):
        assert a.dtype == b.dtype and a.shape == b.shape and torch.equal(a, b), name
    ref_grown = runs.grow_runs(*grow)
    for name, a, b in zip(runs.GrownRuns._fields, grown, ref_grown):
        if isinstance(a, float):  # shares: counted exactly by the kernel, a float32 mean (0-d tensor) by torch
            assert a == pytest.approx(float(b), abs=1e-6), name
        else:
            assert a.dtype == b.dtype and torch.equal(a, b), name
    if shape[-1] > 5 and settings.outlier_test is not None:  # every branch reached (none leaves an infinite test)
        for name in ("outlier", "held_out", "averaged", "restarted", "fresh"):
            flags = getattr(ref, name)
            assert bool(flags.any()) and not bool(flags.all()), name


def test_a_run_is_fresh_until_it_is_settled():
    """``fresh`` (the later layers run there, nothing is held): changed, or a static run younger than
    ``settled_frames`` (``max_frames`` when None); with 1 only the changed pixels."""
    args = _inputs((1, 1, 20, 30), torch.float32, 3)
    static, age = args[2], args[8]
    for settings, settled in ((StreamConfig(), 8), (StreamConfig(settled_frames=3), 3),
                              (StreamConfig(settled_frames=1), 1)):
        fresh = runs.join_runs(*args, settings).fresh
        assert torch.equal(fresh, ~static | (age + 1 < settled))
    assert torch.equal(runs.join_runs(*args, StreamConfig(settled_frames=1)).fresh, ~static)


@pytest.mark.parametrize("numba", [True, False])
def test_a_hole_the_past_never_measured_confidently_is_not_pulled_to_the_past(monkeypatch, numba):
    """By default (``unmeasured_frames`` 0) a static hole whose evidence is below ``fill_evidence`` gets no temporal
    weight: its fill is the frame's own (beside a moving object such a hole, a stereo shadow, was pulled to where
    the mover had been); one with evidence gets weight × age; with ``unmeasured_frames`` 2, weight × min(age, 2)."""
    if not numba:
        monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    y, observed, static, candidate, noise, evidence, mean, departed, age, offset, scale = _inputs((1, 1, 8, 9),
                                                                                              torch.float32, 3)
    observed, static = torch.zeros_like(observed), torch.ones_like(static)  # every pixel a static hole
    y = torch.zeros_like(y)
    evidence = torch.where(torch.arange(72).view(1, 1, 8, 9) % 2 == 0, torch.full_like(evidence, 0.5),
                           torch.full_like(evidence, 3.0))
    age = torch.full_like(age, 6.0)
    args = (y, observed, static, candidate, noise, evidence, mean, departed, age, offset, scale)
    unconfident = evidence < 1.0
    for settings, pull in ((StreamConfig(), 0.0), (StreamConfig(unmeasured_frames=2.0), 2.0)):
        weight = runs.join_runs(*args, settings).weight
        assert torch.equal(weight[unconfident], torch.full_like(weight[unconfident], settings.weight * pull))
        assert torch.equal(weight[~unconfident], torch.full_like(weight[~unconfident], settings.weight * 6.0))
