"""The streaming restorer (issue 28 item 1): the first frame is restore_depth's, reset(), batched streams, less
flicker on a static scene, no trail behind a moving object, holes filled only from a confident past, inputs left
alone, numpy/uint16 in and out, training through a stream; the change test, the reused matches and the recordings
factory."""
from __future__ import annotations

import importlib.util

import numpy as np
import pytest
import torch

from torch_depth_sr import DepthRestorer, StreamRestorer, restore_depth
from torch_depth_sr.config import RestorerConfig, StreamConfig
from torch_depth_sr.errors import ShapeError
from torch_depth_sr.stream import DEFAULT_STREAM_MODEL, default_stream_model, with_stream
from torch_depth_sr.terms import TemporalPriorTerm

H, W = 40, 48


def small_model(**kw) -> DepthRestorer:
    """A quick model: 3 layers, a 7x7 window, 6 matches."""
    return DepthRestorer(num_layers=3, block_matching={"search_window": 7, "k": 6, "match_layers": (1,)}, **kw)


def _scene(seed: int = 0):
    """Two slanted planes of different colour and depth (mm), a depth gap at the middle column."""
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    gt = np.where(xx < W // 2, 1000 + 2 * yy, 1600 + xx).astype(np.float32)
    rgb = np.zeros((3, H, W), np.float32)
    rgb[:, :, : W // 2] = np.array([0.8, 0.3, 0.2], np.float32)[:, None, None]
    rgb[:, :, W // 2:] = np.array([0.2, 0.4, 0.8], np.float32)[:, None, None]
    rgb += 0.05 * np.sin(xx / 3)[None]  # texture
    return gt, rgb


def _noisy(gt: np.ndarray, t: int, sigma: float = 6.0, holes: float = 0.03) -> np.ndarray:
    rng = np.random.default_rng(1000 + t)
    d = np.round(gt + sigma * rng.standard_normal(gt.shape))
    d[rng.random(gt.shape) < holes] = 0
    return d.astype(np.uint16)


def test_first_frame_is_restore_depth_bit_for_bit():
    gt, rgb = _scene()
    d = _noisy(gt, 0)
    m = small_model()
    s = StreamRestorer(m)
    assert np.array_equal(s.step(d, rgb.transpose(1, 2, 0)), restore_depth(d, rgb.transpose(1, 2, 0), model=m))
    # torch float, trusted fill, details: the same as the model's
    y = torch.from_numpy(d.astype(np.float32))[None, None]
    s.reset()
    r = s.step(y, torch.from_numpy(rgb)[None], return_details=True, fill="trusted")
    ref = restore_depth(y, torch.from_numpy(rgb)[None], model=m, return_details=True, fill="trusted")
    assert torch.equal(torch.nan_to_num(r.depth, 7.0), torch.nan_to_num(ref.depth, 7.0))
    assert torch.equal(r.confidence, ref.confidence) and torch.equal(r.trusted, ref.trusted)
    assert not bool(r.static.any()) and r.info["stream"]["frame"] == 0


def test_default_model_is_the_model_the_settings_were_fitted_for_and_the_per_frame_model_is_untouched():
    s = StreamRestorer()
    fast = DepthRestorer.from_pretrained(DEFAULT_STREAM_MODEL)  # denoise-fast, the fast tier until 2026-12-05
    assert s.settings == fast.config.stream and s.settings != StreamConfig()  # its fitted settings (layers 1)
    assert all(torch.equal(a, b) for a, b in zip(s.model.state_dict().values(), fast.state_dict().values()))
    assert DepthRestorer().config.stream is None
    m = small_model()
    before = repr(m)
    StreamRestorer(m)
    assert repr(m) == before  # the stream's term lives in its own variant of the layers
    assert not any(isinstance(t, TemporalPriorTerm) for layer in m.layers for t in layer.terms["denoise"])


def test_reset_starts_a_new_stream():
    gt, rgb = _scene()
    m = small_model()
    s = StreamRestorer(m)
    for t in range(3):
        s.step(_noisy(gt, t), rgb)
    d = _noisy(gt, 9)
    assert not np.array_equal(s.step(d, rgb), restore_depth(d, rgb[None], model=m))
    s.reset()
    assert s.state is None and s.frames == 0
    assert np.array_equal(s.step(d, rgb), restore_depth(d, rgb[None], model=m))


def test_batched_streams_equal_one_stream_each():
    gt, rgb = _scene()
    gt2 = gt[:, ::-1].copy() + 50
    m = small_model()
    batched, one, two = StreamRestorer(m), StreamRestorer(m), StreamRestorer(m)
    rgbs = torch.from_numpy(np.stack([rgb, rgb[:, :, ::-1].copy()]))
    for t in range(4):
        a = torch.from_numpy(_noisy(gt, t).astype(np.float32))
        b = torch.from_numpy(_noisy(gt2, 50 + t).astype(np.float32))
        out = batched.step(torch.stack([a, b])[:, None], rgbs)
        ra = one.step(a[None, None], rgbs[:1])
        rb = two.step(b[None, None], rgbs[1:])
        torch.testing.assert_close(out, torch.cat([ra, rb]), rtol=1e-5, atol=1e-3)


def test_a_mover_in_one_stream_of_a_batch_leaves_the_other_as_it_would_be_alone():
    """Each sample's later layers update its own fresh pixels (a mover in one sample, a still scene in the other):
    the batch gives each stream's frames as one stream each."""
    from torch_depth_sr.datasets.synthetic import make_scene

    s = make_scene(48, 64, seed=1)
    gt, rgb = s["gt"], s["rgb"]

    def frames(seed, moving):
        g = torch.Generator().manual_seed(seed)
        for t in range(8):
            d, c = gt + 2 * torch.randn(gt.shape, generator=g), rgb.clone()
            if moving and t >= 5:
                d[..., 20:30, 10 + 3 * t:20 + 3 * t] = 500.0
                c[..., 20:30, 10 + 3 * t:20 + 3 * t] = 0.9
            yield d, c
    m = default_stream_model().eval()
    batched, one, two = StreamRestorer(m), StreamRestorer(m), StreamRestorer(m)
    with torch.no_grad():
        for (d1, c1), (d2, c2) in zip(frames(1, True), frames(2, False)):
            out = batched(torch.stack([d1, d2]), torch.stack([c1, c2]))
            alone = torch.cat([one(d1[None], c1[None]), two(d2[None], c2[None])])
            torch.testing.assert_close(out, alone, rtol=1e-5, atol=1e-3)
    assert (out[0, :, 21:29, 33:39] - 500.0).abs().max() < 5.0  # the mover, restored where it is now


def test_a_frame_of_another_size_needs_reset():
    gt, rgb = _scene()
    s = StreamRestorer(small_model())
    s.step(_noisy(gt, 0), rgb)
    with pytest.raises(ShapeError, match="reset"):
        s.step(_noisy(gt, 1)[:, :40], rgb[:, :, :40])


def _restore_all(make, frames, rgbs):
    out = []
    for d, c in zip(frames, rgbs):
        out.append(make(d, c).astype(np.float64))
    return np.stack(out)


def test_a_static_scene_flickers_less_than_frame_by_frame():
    gt, rgb = _scene()
    m = small_model()
    s = StreamRestorer(m)
    frames = [_noisy(gt, t) for t in range(8)]
    per_frame = _restore_all(lambda d, c: restore_depth(d, c[None], model=m), frames, [rgb] * 8)
    stream = _restore_all(lambda d, c: s.step(d, c), frames, [rgb] * 8)
    f_frame = (per_frame[3:] - gt).std(0).mean()
    f_stream = (stream[3:] - gt).std(0).mean()
    assert f_stream < 0.6 * f_frame, (f_stream, f_frame)
    rmse = lambda o: np.sqrt(((o[3:] - gt) ** 2).mean())  # noqa: E731
    assert rmse(stream) < rmse(per_frame)


def _moving_square(t: int):
    """A near square (600 mm, green) moving 3 px per frame to the right over the two planes."""
    gt, rgb = _scene()
    gt, rgb = gt.copy(), rgb.copy()
    x0 = 4 + 3 * t
    gt[12:26, x0:x0 + 12] = 600
    rgb[:, 12:26, x0:x0 + 12] = np.array([0.1, 0.9, 0.1], np.float32)[:, None, None]
    return gt, rgb


def test_a_moving_object_leaves_no_trail():
    m = small_model()
    s = StreamRestorer(m)
    err_stream, err_frame = [], []
    for t in range(8):
        gt, rgb = _moving_square(t)
        d = _noisy(gt, t)
        a, b = s.step(d, rgb).astype(np.float64), restore_depth(d, rgb[None], model=m).astype(np.float64)
        if t >= 2:  # near the square now and where it was in the two frames before
            near = np.zeros_like(gt, bool)
            for k in range(3):
                x0 = 4 + 3 * (t - k)
                near[10:28, max(0, x0 - 2):x0 + 14] = True
            err_stream.append(np.abs(a - gt)[near])
            err_frame.append(np.abs(b - gt)[near])
    rmse = lambda e: float(np.sqrt(np.mean(np.concatenate(e) ** 2)))  # noqa: E731
    assert rmse(err_stream) <= 1.05 * rmse(err_frame), (rmse(err_stream), rmse(err_frame))
    # the background the square uncovered is the background, not the square
    gt, _ = _moving_square(7)
    uncovered = np.zeros_like(gt, bool)
    uncovered[12:26, 4 + 3 * 5:4 + 3 * 7] = True
    assert np.abs(a - gt)[uncovered].max() < 100


def test_holes_are_filled_only_from_a_confident_past_never_across_a_gap():
    gt, rgb = _scene()
    m = small_model()
    s = StreamRestorer(m, fill="trusted")
    gap = slice(W // 2 - 4, W // 2 + 4)  # columns around the depth gap (the colours differ, the fill is ambiguous)
    # the gap band measured in the first frames: later holes there are filled from the past, on the right side
    for t in range(4):
        s.step(_noisy(gt, t, holes=0.0), rgb)
    d = _noisy(gt, 4, holes=0.0)
    d[10:30, gap] = 0
    r = s.step(d, rgb, return_details=True)
    filled = r.depth[10:30, gap].astype(np.float64)
    assert (filled > 0).all()
    assert np.abs(filled - gt[10:30, gap]).max() < 30  # the past value of each side, not a blend across the gap
    assert (r.confidence[10:30, gap] > 0).all()


def test_a_single_departure_from_a_static_run_is_held_out_and_a_repeated_one_starts_a_new_mean():
    """At a depth edge a mixed pixel takes the other side's depth in single frames: the first departure from a
    confident run is held out (the run's mean and the output stay), the same departure in the next frame starts a
    new mean."""
    gt, rgb = _scene()
    s = StreamRestorer(small_model())
    for t in range(5):
        s.step(_noisy(gt, t, holes=0.0), rgb)
    rows, col = [4, 12, 20, 28], W // 2 - 1  # the left side's last column; its right neighbour is 600 mm farther
    before = s.state.mean[0, 0, rows, col].clone()
    d = _noisy(gt, 5, holes=0.0)
    d[rows, col] = np.round(gt[rows, col + 1]).astype(np.uint16)
    r = s.step(d, rgb, return_details=True)
    assert r.info["stream"]["held_out"] > 0
    assert np.abs(r.depth[rows, col].astype(np.float64) - gt[rows, col]).max() < 30
    assert torch.allclose(s.state.mean[0, 0, rows, col], before)  # the run goes on without the departure
    assert (s.state.departed[0, 0, rows, col] > 0).all()
    d = _noisy(gt, 6, holes=0.0)
    d[rows, col] = np.round(gt[rows, col + 1]).astype(np.uint16)
    s.step(d, rgb)
    new = torch.from_numpy(d[rows, col].astype(np.float32))
    assert torch.allclose(s.state.mean[0, 0, rows, col].float(), new)  # confirmed: a new mean, the measurement
    assert (s.state.departed[0, 0, rows, col] == 0).all()


def test_a_thin_object_of_unchanged_colour_appears_and_leaves_within_one_frame():
    """A pole one pixel wide, 340 mm in front of a static plane and of the plane's colour: no window of the change
    test sees it, and its measurements match no previous value near them (outliers in time). The stream holds them
    out for one frame only: from the second frame it shows the pole, as frame-by-frame restoration does, and one frame
    after the pole has gone, the plane again."""
    gt, rgb = _scene()
    m = small_model()
    s = StreamRestorer(m)
    for t in range(10):
        s.step(_noisy(gt, t, holes=0.0), rgb)
    pole = (slice(8, 32), 10)

    def with_pole(t):
        d = _noisy(gt, t, holes=0.0)
        d[pole] = 700
        return d

    assert np.median(restore_depth(with_pole(10), rgb[None], model=m)[pole]) < 720  # the frame alone sees it
    s.step(with_pole(10), rgb)
    for t in (11, 12):
        assert np.median(s.step(with_pole(t), rgb)[pole].astype(np.float64)) < 720
    s.step(_noisy(gt, 13, holes=0.0), rgb)
    out = s.step(_noisy(gt, 14, holes=0.0), rgb)[pole].astype(np.float64)
    assert np.abs(np.median(out) - np.median(gt[pole])) < 20


def test_never_measured_holes_stay_holes_after_the_first_frame():
    """A hole the past never measured keeps the first frame's verdict while it stays a hole and its colour does not
    change: it never turns into a fill from the past."""
    gt, rgb = _scene()
    m = small_model()
    s = StreamRestorer(m, fill="trusted")
    never = np.zeros_like(gt, bool)
    never[5:35, W // 2 - 4:W // 2 + 4] = True
    verdicts = []
    for t in range(5):
        d = _noisy(gt, t, holes=0.0)
        d[never] = 0
        r = s.step(d, rgb, return_details=True)
        verdicts.append(r.depth[never] > 0)
        assert (r.evidence[never] == 0).all()  # no evidence where nothing was measured
    first = restore_depth(_noisy(gt, 0, holes=0.0) * ~never, rgb[None], model=m, fill="trusted")[never] > 0
    assert all(np.array_equal(v, first) for v in verdicts)


def test_inputs_are_not_modified():
    gt, rgb = _scene()
    s = StreamRestorer(small_model())
    for t in range(3):
        d = _noisy(gt, t)
        d0, c0 = d.copy(), rgb.copy()
        s.step(d, rgb)
        assert np.array_equal(d, d0) and np.array_equal(rgb, c0)
    y = torch.from_numpy(_noisy(gt, 5).astype(np.float32))[None, None]
    y0 = y.clone()
    s(y, torch.from_numpy(rgb)[None])
    assert torch.equal(y, y0)


@pytest.mark.parametrize("layout", ["hw", "1hw"])
def test_numpy_uint16_round_trip(layout):
    gt, rgb = _scene()
    s = StreamRestorer(small_model())
    rgb8 = (rgb.transpose(1, 2, 0) * 255).round().astype(np.uint8)
    for t in range(3):
        d = _noisy(gt, t)
        d = d if layout == "hw" else d[None]
        out = s.step(d, rgb8)
        assert isinstance(out, np.ndarray) and out.dtype == np.uint16 and out.shape == d.shape
        assert (out > 0).all()  # fill="all": every hole filled
    r = s.step(d, rgb8, return_details=True)
    assert r.depth.dtype == np.uint16 and r.confidence.shape == d.shape and r.static.shape == d.shape
    assert isinstance(r.evidence, np.ndarray) and r.info["stream"]["frame"] == 3


def test_gradients_reach_the_model_in_a_training_loop():
    gt, rgb = _scene()
    m = small_model(trainable=True)
    s = StreamRestorer(m)
    assert {id(p) for p in s.parameters()} == {id(p) for p in m.parameters()}  # the model's own parameters
    opt = torch.optim.Adam(m.parameters(), lr=1e-2)
    before = m.layers[0].raw_lam.detach().clone()
    g = torch.from_numpy(gt)[None, None]
    c = torch.from_numpy(rgb)[None]
    for t in range(3):
        y = torch.from_numpy(_noisy(gt, t).astype(np.float32))[None, None]
        out = s(y, c)
        loss = ((out - g) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        grads = [p.grad for p in m.parameters() if p.requires_grad]
        assert all(gr is not None and torch.isfinite(gr).all() for gr in grads)
        assert any(float(gr.abs().sum()) > 0 for gr in grads)
        opt.step()
    assert not torch.equal(before, m.layers[0].raw_lam.detach())
    assert s.state is not None and not s.state.depth.requires_grad  # the state carries no graph


def test_with_stream_shares_everything_but_the_terms():
    m = small_model()
    v = with_stream(m, StreamConfig())
    assert v.block_matcher is m.block_matcher and v.init is m.init
    assert all(a.raw_lam is b.raw_lam for a, b in zip(v.layers, m.layers))
    assert isinstance(v.layers[0].terms["denoise"][-1], TemporalPriorTerm)
    assert with_stream(v, StreamConfig()) is v
    assert DepthRestorer(RestorerConfig(stream={})).config.stream == StreamConfig()


def test_stream_settings_are_checked():
    from torch_depth_sr import ParameterError

    with pytest.raises(ParameterError, match="stream.hole_decay"):
        RestorerConfig(stream={"hole_decay": 2.0})
    s = StreamRestorer(small_model(), {"max_frames": 4})
    assert s.settings.max_frames == 4


def test_a_frame_with_a_previous_one_runs_the_first_layers_setting():
    """``layers``: the first frame runs every layer; a static pixel whose run has its full mean (``max_frames``) gets
    the first ``layers`` only, a changed or younger one every layer, on crops around it: the same as every layer on
    the whole frame where all is changed, one layer where all is old and static; a static scene still flickers less
    than frame by frame."""
    gt, rgb = _scene()
    m = small_model()
    calls = []
    for i, layer in enumerate(m.layers):
        layer.register_forward_hook(lambda mod, args, out, i=i: calls.append(i))
    s = StreamRestorer(m, {"layers": 1, "max_frames": 3})
    frames = [_noisy(gt, t) for t in range(8)]
    stream = _restore_all(lambda d, c: s.step(d, c), frames, [rgb] * 8)
    assert calls[:6] == [0, 1, 2] * 2  # frames 0 and 1: every pixel's run is younger than max_frames
    assert calls[-3:] == [0, 0, 0]  # the last frames: static and old everywhere, one layer
    per_frame = _restore_all(lambda d, c: restore_depth(d, c[None], model=m), frames, [rgb] * 8)
    assert (stream[3:] - gt).std(0).mean() < 0.6 * (per_frame[3:] - gt).std(0).mean()
    # a moved object: its pixels get every layer, on a crop; the rest one
    calls.clear()
    moved = _noisy(gt, 9).astype(np.float32)
    moved[10:20, 5:15] = 700.0
    rgb2 = rgb.copy()
    rgb2[:, 10:20, 5:15] = 0.9
    s.step(moved, rgb2)
    assert calls == [0, 1, 2]
    with pytest.raises(Exception, match="stream.layers"):
        RestorerConfig(stream={"layers": 0})
    assert DepthRestorer.from_pretrained(DEFAULT_STREAM_MODEL).config.stream.layers == 1  # the stream's model has it


def test_later_layers_equal_the_whole_frame_where_everything_changed():
    gt, rgb = _scene()
    m = small_model()
    s = StreamRestorer(m, {"layers": 1})
    s.step(_noisy(gt, 0), rgb)
    every = StreamRestorer(m)
    every.step(_noisy(gt, 0), rgb)
    # a camera that moved: every pixel changed, so both streams run every layer on the whole frame
    shifted = np.roll(_noisy(gt, 1), 3, axis=1)
    rgb_s = np.roll(rgb, 3, axis=2)
    a, b = s.step(shifted, rgb_s), every.step(shifted, rgb_s)
    assert np.array_equal(a, b)


def _moved_object_after_static_frames(monkeypatch, path: str, most: float = 0.5):
    """A stream of a model without re-matching in its later layers: five static frames, then an object moved in;
    the later layers' update regions it ran with are recorded. ``most``: the share of the frame up to which the later
    layers run on crops around the fresh pixels (0: never)."""
    from torch_depth_sr.stream import frame as frame_module
    from torch_depth_sr.stream import later_layers

    gt, rgb = _scene()
    moved = _noisy(gt, 9).astype(np.float32)
    moved[10:20, 5:15] = 700.0
    rgb2 = rgb.copy()
    rgb2[:, 10:20, 5:15] = 0.9
    if path == "device":
        monkeypatch.setenv("TORCH_DEPTH_SR_DEVICE_PATH", "1")
    monkeypatch.setattr(later_layers, "_MOST", most)
    regions = []
    real = frame_module.run_later_layers
    monkeypatch.setattr(frame_module, "run_later_layers",
                        lambda layers, state, obs, fresh: regions.append(fresh.clone()) or real(layers, state, obs,
                                                                                               fresh))
    model = DepthRestorer(num_layers=3, block_matching={"search_window": 7, "k": 6, "match_layers": (0,)})
    s = StreamRestorer(model, {"layers": 1, "max_frames": 3})
    for t in range(5):
        s.step(_noisy(gt, t), rgb)
    before = s.state.depth.clone()
    out = s.step(moved, rgb2, return_details=True)
    monkeypatch.undo()
    return out, regions[-1][0, 0].numpy(), before[0, 0].numpy()


def test_the_later_layers_update_the_fresh_pixels_alone_the_same_on_every_path(monkeypatch):
    """A moved object's pixels get every layer and take its depth; on crops around the fresh pixels or on the whole
    frame (the CPU), with the kernels computing everything (the device path, a GPU's), the frame is the same up to
    round-off."""
    from torch_depth_sr.stream import later_layers

    cut = []
    real = later_layers._cut_state
    monkeypatch.setattr(later_layers, "_cut_state", lambda *a: cut.append(1) or real(*a))
    outs = {(path, most): _moved_object_after_static_frames(monkeypatch, path, most)
            for path, most in (("host", 1.0), ("host", 0.0), ("device", 1.0))}
    host, fresh, _ = outs[("host", 1.0)]
    assert cut and fresh[10:20, 5:15].all() and 0 < fresh.mean() < 0.5  # crops were cut
    for other in (outs[("host", 0.0)], outs[("device", 1.0)]):
        assert np.array_equal(fresh, other[1])
        assert np.abs(host.depth - other[0].depth).max() < 1e-3
    assert np.abs(host.depth[10:20, 5:15] - 700.0).max() < 5.0


def test_a_later_layer_with_an_update_region_holds_every_other_pixel():
    """``Observation.update_region``: the layer's x-update solves for the region alone and every other pixel keeps
    the state it came in with, bit for bit, the gate its verdict; in the region the values move."""
    gt, rgb = _scene()
    m = small_model().eval()
    seen = {}

    def spy(layer, args, out):
        state, obs = args
        if obs.update_region is not None:
            seen["pair"] = (state, obs.update_region, out)
    hooks = [layer.register_forward_hook(spy) for layer in m.layers]
    s = StreamRestorer(m, {"layers": 1, "max_frames": 3})
    for t in range(5):
        s.step(_noisy(gt, t), rgb)
    moved = _noisy(gt, 9).astype(np.float32)
    moved[10:20, 5:15] = 700.0
    rgb2 = rgb.copy()
    rgb2[:, 10:20, 5:15] = 0.9
    s.step(moved, rgb2)
    for h in hooks:
        h.remove()
    state, region, out = seen["pair"]
    assert 0 < region.float().mean() < 0.5
    for name in ("x", "z", "w", "e", "alpha", "q", "confidence"):
        before, after = getattr(state, name), getattr(out, name)
        outside = ~region.expand_as(after)
        assert torch.equal(after[outside], before.to(after)[outside]), name
    assert (out.x - state.x)[region].abs().max() > 0
    assert state.clean is not None and torch.equal(out.clean, state.clean)  # the gate keeps its verdict


def test_change_test_sees_motion_and_ignores_noise_and_outliers():
    from torch_depth_sr.stream import change_test

    g = torch.Generator().manual_seed(0)
    prev = torch.full((1, 1, 32, 32), 10.0)
    y = prev + torch.randn(prev.shape, generator=g)  # noise of 1
    y[0, 0, 5, 5] = 40.0  # an impulse
    y[0, 0, 16:24, 16:24] += 8.0  # a surface that moved
    rgb = torch.rand(1, 3, 32, 32, generator=g)
    t = change_test(y, torch.ones_like(y), prev, torch.tensor([1.0]), rgb, rgb.clone(), StreamConfig())
    assert bool(t.changed[0, 0, 18:22, 18:22].all()) and not bool(t.changed[0, 0, :10, :10].any())
    assert bool(t.outlier[0, 0, 5, 5]) and int(t.outlier.sum()) <= 3
    rgb2 = rgb.clone()
    rgb2[..., 2:6, 26:30] = 1 - rgb2[..., 2:6, 26:30]  # a colour change without a depth change
    t2 = change_test(prev, torch.ones_like(y), prev, torch.tensor([1.0]), rgb2, rgb, StreamConfig())
    assert bool(t2.changed[0, 0, 3, 27]) and not bool(t2.changed[0, 0, 20, 5])


def test_a_moving_camera_changes_every_pixel():
    from torch_depth_sr.stream import change_test
    from torch_depth_sr.stream.change import camera_moved

    g = torch.Generator().manual_seed(1)
    rgb = torch.rand(1, 3, 40, 48, generator=g)
    moved = torch.roll(rgb, shifts=(1, 2), dims=(2, 3))
    assert float(camera_moved(moved, rgb)) < 0.5 and float(camera_moved(rgb, rgb)) == 1.0
    one = rgb.clone()
    one[..., 10:20, 10:20] = torch.rand(1, 3, 10, 10, generator=g)  # an object, not the camera
    assert float(camera_moved(one, rgb)) > 0.9
    depth = torch.full((1, 1, 40, 48), 5.0)
    t = change_test(depth, torch.ones_like(depth), depth, torch.tensor([1.0]), moved, rgb, StreamConfig())
    assert bool(t.changed.all())


def test_reused_matches_equal_the_search_where_it_runs():
    from torch_depth_sr.observation import observe
    from torch_depth_sr.operators import Identity
    from torch_depth_sr.stream import StreamMatcher

    m = DepthRestorer(block_matching={"search_window": 9, "k": 8})
    gt, rgb = _scene()
    y = torch.from_numpy(_noisy(gt, 0, holes=0.0).astype(np.float32))[None, None]
    c = torch.from_numpy(rgb)[None]
    obs = observe(y, torch.ones_like(y), c, Identity(), None, True, m.block_matcher, False)
    full = m.block_matcher(obs.y, obs, obs.observed)
    fresh = torch.zeros_like(y, dtype=torch.bool)
    fresh[..., 10:16, 20:30] = True
    kept = (full.dist.flip(1), full.index.flip(1))
    sm = StreamMatcher(m.block_matcher, kept, fresh)
    mix = sm(obs.y, obs, obs.observed)
    f = fresh.expand_as(full.index)
    assert torch.equal(mix.index[f], full.index[f]) and torch.equal(mix.index[~f], kept[1][~f])
    assert torch.equal(mix.dist[f], full.dist[f])  # to the last bit: the whole image's block sums, not a crop's
    assert sm.searched < H * W  # a crop, not the whole frame
    again = sm.rematch(obs.y, obs, obs.observed, full)
    whole = m.block_matcher.rematch(obs.y, obs, obs.observed, full)
    assert torch.equal(again.index[f], whole.index[f]) and torch.equal(again.dist[f], whole.dist[f])


def test_kept_match_weights_are_the_softmax_again_and_skipped_when_the_temperature_learns():
    from torch_depth_sr.observation import observe
    from torch_depth_sr.operators import Identity
    from torch_depth_sr.stream import StreamMatcher

    m = DepthRestorer(block_matching={"search_window": 9, "k": 8}, trainable=True)
    gt, rgb = _scene()
    y = torch.from_numpy(_noisy(gt, 0, holes=0.0).astype(np.float32))[None, None]
    obs = observe(y, torch.ones_like(y), torch.from_numpy(rgb)[None], Identity(), None, True, m.block_matcher, False)
    with torch.no_grad():
        full = m.block_matcher(obs.y, obs, obs.observed)
    kept = (full.dist.detach(), full.index)
    nothing = torch.zeros_like(y, dtype=torch.bool)
    made_at = m.block_matcher.temperature.detach().clone()
    with torch.no_grad():
        fresh = StreamMatcher(m.block_matcher, kept, nothing)(obs.y, obs, obs.observed)
        stale = torch.full_like(full.weight, 0.5)  # not a softmax: shows whether it was returned
        cached = StreamMatcher(m.block_matcher, kept, nothing, (stale, made_at))(obs.y, obs, obs.observed)
        assert cached.weight is stale
        other = StreamMatcher(m.block_matcher, kept, nothing, (stale, made_at * 2))(obs.y, obs, obs.observed)
        assert torch.equal(other.weight, fresh.weight)  # made at another temperature: computed again
    # a learning temperature needs the softmax's gradient
    learning = StreamMatcher(m.block_matcher, kept, nothing, (stale, made_at))(obs.y, obs, obs.observed)
    assert learning.weight.requires_grad and torch.allclose(learning.weight, fresh.weight)
    # some pixels fresh: the kept weights elsewhere, the softmax of the new lists on the crops, as without them (to
    # the last bit of torch's vectorised exp, which a crop's layout can change)
    some = nothing.clone()
    some[..., 11:14, 17:30] = True
    with torch.no_grad():
        new = StreamMatcher(m.block_matcher, (kept[0].clone(), kept[1].clone()), some)(obs.y, obs, obs.observed)
        cached = StreamMatcher(m.block_matcher, (kept[0].clone(), kept[1].clone()), some,
                               (fresh.weight.clone(), made_at))(obs.y, obs, obs.observed)
    assert torch.equal(cached.index, new.index) and torch.allclose(cached.weight, new.weight, rtol=1e-6, atol=1e-7)
    outside = ~some.expand_as(new.weight)
    assert torch.equal(cached.weight[outside], fresh.weight[outside])


@pytest.mark.parametrize("search", ["masked", "crops"])
def test_a_batch_of_streams_searches_each_samples_fresh_pixels_and_keeps_the_others(monkeypatch, search):
    """Two streams in a batch, fresh at different pixels: each sample's fresh pixels get the whole batch image's
    matches and their softmax, the other pixels keep their matches and weights; by the CPU's masked search, and by
    the crops that run where it does not (another device)."""
    from torch_depth_sr.observation import observe
    from torch_depth_sr.operators import Identity
    from torch_depth_sr.stages import BlockMatcher
    from torch_depth_sr.stream import StreamMatcher

    if search == "crops":
        monkeypatch.setattr(BlockMatcher, "search_at", lambda *a, **k: False)
    m = DepthRestorer(block_matching={"search_window": 9, "k": 8})
    gt, rgb = _scene()
    y = torch.from_numpy(np.stack([_noisy(gt, t, holes=0.0) for t in (0, 1)]).astype(np.float32))[:, None]
    c = torch.from_numpy(rgb)[None].expand(2, -1, -1, -1)
    obs = observe(y, torch.ones_like(y), c, Identity(), None, True, m.block_matcher, False)
    with torch.no_grad():
        full = m.block_matcher(obs.y, obs, obs.observed)
        fresh = torch.zeros_like(y, dtype=torch.bool)
        fresh[0, :, 4:9, 3:20] = True
        fresh[1, :, 20:31, 25:29] = True
        stale = torch.full_like(full.weight, 0.5)  # not a softmax: the kept weights show where they stay
        made_at = m.block_matcher.temperature.detach().clone()
        kept = (full.dist.flip(1).contiguous(), full.index.flip(1).contiguous())
        mix = StreamMatcher(m.block_matcher, kept, fresh, (stale.clone(), made_at))(obs.y, obs, obs.observed)
    f = fresh.expand_as(full.index)
    assert torch.equal(mix.index[f], full.index[f]) and torch.equal(mix.dist[f], full.dist[f])
    assert torch.allclose(mix.weight[f], full.weight[f], rtol=1e-6, atol=1e-7)
    assert torch.equal(mix.index[~f], full.index.flip(1)[~f]) and bool((mix.weight[~f] == 0.5).all())


def test_a_static_stream_keeps_its_scale_policy_and_a_changed_one_estimates_it_again(monkeypatch):
    """keep_scale: while most of the previous frame was static a frame is normalised with the previous frame's
    offset, scale range and grid step, its noise level a running mean of quarter-row estimates; a frame after a
    mostly changed one (a moved camera) estimates them again; off: every frame its own."""
    import torch_depth_sr.model as model_module
    import torch_depth_sr.observation as observation

    seen = []

    def spy(*args, policy=None, **kw):
        obs = observation.observe(*args, policy=policy, **kw)
        seen.append((policy is not None, obs.policy))
        return obs

    monkeypatch.setattr(model_module, "observe", spy)
    gt, rgb = _scene()
    m = small_model()
    s = StreamRestorer(m)
    for t in range(4):
        s.step(_noisy(gt, t), rgb)
    assert [k for k, _ in seen] == [False, True, True, True]  # the first frame estimates, the others keep
    first, last = seen[0][1], seen[-1][1]
    assert torch.equal(first.offset, last.offset) and torch.equal(first.percentiles, last.percentiles)
    assert not torch.equal(first.sigma, last.sigma)  # the noise level is still averaged over frames
    torch.testing.assert_close(last.sigma, first.sigma, rtol=0.2, atol=0)
    seen.clear()
    s.step(np.roll(_noisy(gt, 5), 3, axis=1), np.roll(rgb, 3, axis=2))  # the camera moved: every pixel changed
    s.step(np.roll(_noisy(gt, 6), 3, axis=1), np.roll(rgb, 3, axis=2))
    assert [k for k, _ in seen] == [True, False]  # the frame after the move estimates again
    seen.clear()
    off = StreamRestorer(m, {"keep_scale": False})
    for t in range(3):
        off.step(_noisy(gt, t), rgb)
    assert [k for k, _ in seen] == [False, False, False]


def _wall(rng: np.random.Generator, arrival: bool) -> np.ndarray:
    """A still wall (1500-1625 mm: a narrow range, so 700 mm is far outside it) measured with noise σ 4 mm; with
    ``arrival``, a person at 700 mm in rows 10-19, columns 8-19."""
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    scene = 1500 + 2 * yy + xx
    if arrival:
        scene[10:20, 8:20] = 700
    return np.round(scene + 4 * rng.standard_normal(scene.shape)).astype(np.uint16)


def test_an_object_outside_the_kept_policys_range_is_a_surface_not_a_glitch():
    """A kept scale policy calls values far outside the still scene's range implausible (sensor glitches). A person
    arriving 0.8 m in front of a wall is no glitch: the frame's policy is estimated again, and the stream shows the
    person where it measured them, not the wall it remembers behind them, in each frame that follows."""
    rng = np.random.default_rng(0)
    rgb = np.zeros((3, H, W), np.float32)
    rgb[:] = np.array([0.2, 0.4, 0.8], np.float32)[:, None, None]
    s = StreamRestorer(small_model())
    s.step(_wall(rng, arrival=False), rgb)
    colour = rgb.copy()
    colour[:, 10:20, 8:20] = np.array([0.9, 0.2, 0.1], np.float32)[:, None, None]
    for t in range(3):
        out = np.asarray(s.step(_wall(rng, arrival=True), colour), dtype=np.float64)
        assert np.abs(out[11:19, 9:19] - 700).max() < 25, (t, out[11:19, 9:19].mean())


@pytest.mark.parametrize("device_path", [False, True])
def test_a_kept_policy_is_estimated_again_only_in_the_sample_that_leaves_its_range(device_path, monkeypatch):
    """Per sample: the sample with an arrival outside the kept range takes the frame's own estimate, the other keeps
    the policy; the device path (no host read) picks the same."""
    from torch_depth_sr.observation import observe
    from torch_depth_sr.operators import Identity

    if device_path:
        monkeypatch.setenv("TORCH_DEPTH_SR_DEVICE_PATH", "1")
    rng = np.random.default_rng(0)
    y = torch.from_numpy(np.stack([_wall(rng, arrival=False) for _ in range(2)]))[:, None].float()
    obs = torch.ones_like(y)
    K = Identity()
    policy = observe(y, obs, None, K, None, True, None, False).policy  # the still scene's, per sample
    moved = y.clone()
    moved[0, 0] = torch.from_numpy(_wall(rng, arrival=True)).float()  # sample 0: a person arrives
    o = observe(moved, obs, None, K, None, True, None, False, policy=policy)
    fresh = observe(moved, obs, None, K, None, True, None, False)
    assert not bool(o.glitches.any())  # the arrival is measured
    torch.testing.assert_close(o.percentiles[0], fresh.percentiles[0], rtol=0, atol=0)
    torch.testing.assert_close(o.offset[0], fresh.offset[0], rtol=0, atol=0)
    torch.testing.assert_close(o.percentiles[1], policy.percentiles[1], rtol=0, atol=0)  # sample 1 keeps its own
    torch.testing.assert_close(o.offset[1], policy.offset[1], rtol=0, atol=0)


def test_a_given_noise_level_makes_a_kept_scale_policy_estimate_nothing(monkeypatch):
    import torch_depth_sr.stream.frame as frame

    def refuse(*args, **kw):
        raise AssertionError("σ̂ estimated although the caller gave it")

    monkeypatch.setattr(frame, "sampled_noise_sigma", refuse)
    gt, rgb = _scene()
    s = StreamRestorer(small_model(), noise_sigma=6.0)
    outs = [s.step(_noisy(gt, t), rgb, return_details=True) for t in range(3)]
    assert all(r.info["noise_sigma"] == [6.0] for r in outs)


def test_sampled_noise_sigma_estimates_the_noise_from_a_quarter_of_the_rows(monkeypatch):
    from torch_depth_sr.noise import estimate_noise_sigma, sampled_noise_sigma

    g = torch.Generator().manual_seed(0)
    y = 500 + 0.5 * torch.arange(240.0).view(1, 1, 240, 1) + 3 * torch.randn(2, 1, 240, 320, generator=g)
    observed = (torch.rand(y.shape, generator=g) > 0.1).float()
    full = estimate_noise_sigma(y, observed)
    for phase in (1, 2, 3):
        torch.testing.assert_close(sampled_noise_sigma(y, observed, phase), full, rtol=0.05, atol=0)
    assert torch.equal(sampled_noise_sigma(y[..., :1, :], observed[..., :1, :], 1),
                       estimate_noise_sigma(y[..., :1, :], observed[..., :1, :]))  # no row to sample: all of them
    host = sampled_noise_sigma(y, observed, 2)
    monkeypatch.setenv("TORCH_DEPTH_SR_DEVICE_PATH", "1")  # every sample at once, as on a GPU: the same medians
    assert torch.equal(sampled_noise_sigma(y, observed, 2), host)


def test_recordings_factory_streams_and_replays(tmp_path):
    import cv2

    from torch_depth_sr.recordings import PretrainedRestorer, restore_dataset

    gt, rgb = _scene()
    root = tmp_path / "rec"
    for t in range(3):
        (root / "depth").mkdir(parents=True, exist_ok=True)
        (root / "rgb").mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(root / "depth" / f"{t:03d}.png"), _noisy(gt, t))
        cv2.imwrite(str(root / "rgb" / f"{t:03d}.png"), (rgb.transpose(1, 2, 0)[..., ::-1] * 255).astype(np.uint8))
    factory = PretrainedRestorer(None, stream=True)
    restorer = factory()
    assert restorer.stateful
    assert restorer.stream.settings == default_stream_model().config.stream  # no name: StreamRestorer()'s
    factory._model = small_model()  # a quick model for the test
    summary = restore_dataset(root, tmp_path / "out", restorer=factory, progress=False)
    assert summary.ok and summary.written == 3
    stream = StreamRestorer(small_model())
    for t in range(3):
        d = cv2.imread(str(root / "depth" / f"{t:03d}.png"), cv2.IMREAD_UNCHANGED)
        c = torch.from_numpy(cv2.cvtColor(cv2.imread(str(root / "rgb" / f"{t:03d}.png")), cv2.COLOR_BGR2RGB)
                             .astype(np.float32) / 255).permute(2, 0, 1)
        expected = stream.step(d, c[None])
        written = cv2.imread(str(tmp_path / "out" / "rec" / "depth" / f"{t:03d}.png"), cv2.IMREAD_UNCHANGED)
        assert np.array_equal(written, expected), t


_NO_REALSENSE = pytest.mark.skipif(importlib.util.find_spec("pyrealsense2") is None,
                                   reason="pyrealsense2 is an optional benchmark extra (bench-stream), not installed")


@pytest.mark.parametrize("name", ["frame", "stream", pytest.param("rs-temporal+frame", marks=_NO_REALSENSE)])
@pytest.mark.parametrize("given", [False, True])
def test_stream_track_methods_run_their_model_on_the_requested_device(name, given):
    # the colour goes to `device`; the model computes where its parameters are, so it must be moved there too
    # ("meta" stands for a device other than the CPU: a model on the CPU must leave it)
    from torch_depth_sr.evaluation.stream import make_method

    model = DepthRestorer(num_layers=1) if given else None
    method = make_method(name, model, device="meta")
    devices = {p.device for p in method.model.parameters()} | {b.device for b in method.model.buffers()}
    assert devices == {torch.device("meta")}
    if given:
        assert method.model is model


def test_stream_track_method_on_cpu_restores():
    from torch_depth_sr.evaluation.stream import make_method

    d = np.full((24, 32), 1000, np.uint16)
    d[5:9, 5:9] = 0
    method = make_method("stream", DepthRestorer(num_layers=1), device="cpu")
    assert {p.device for p in method.model.parameters()} == {torch.device("cpu")}
    for _ in range(2):
        out = method.step(d, torch.zeros(3, 24, 32))
    assert out.shape == d.shape


def _still_sequence(t=4, h=12, w=16):
    """A synthetic sequence without movers: its trail region is empty."""
    gt = np.full((t, 1, h, w), 1000.0, np.float32)
    return {"gt": gt, "depth": gt.astype(np.uint16), "rgb": np.zeros((t, 3, h, w), np.float32),
            "moving": np.zeros((t, 1, h, w), bool), "hold_from": 0}


def test_trail_of_a_sequence_without_movers_is_nan_and_left_out_of_the_means(monkeypatch):
    import warnings

    from torch_depth_sr.evaluation import stream as track

    seq = _still_sequence()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "Mean of empty slice": the empty region is handled, not stumbled on
        m = track.synthetic_metrics(seq["gt"][:, 0] + 1, seq)
    assert np.isnan(m["trail"]) and m["rmse"] == pytest.approx(1.0)
    rows = [{"set": "synthetic", "sequence": n, "method": "raw", "trail": v} for n, v in (("a", m["trail"]),
                                                                                          ("b", 3.0), ("c", 5.0))]
    assert track.summarise(rows)[0]["trail"] == 4.0


@_NO_REALSENSE
def test_realsense_tuning_leaves_a_sequence_without_trail_out_of_the_mean(monkeypatch):
    # tune_realsense: one tuning sequence without a trail must not make the mean trail NaN
    from torch_depth_sr.evaluation import stream as track

    regions = track.regions
    seen = []

    def no_trail_in_the_first(seq):
        reg = regions(seq)
        if not seen:
            reg["trail"] = np.zeros_like(reg["trail"])
        seen.append(1)
        return reg
    monkeypatch.setattr(track, "regions", no_trail_in_the_first)
    res = track.tune_realsense(frames=16, size=(32, 40), grid=dict(alpha=(0.1,), delta=(50.0,), persistence=(0,)))
    assert len(res) == 1 and np.isfinite(res[0]["trail"]) and np.isfinite(res[0]["rmse"])


def _state_tensors(stream):
    st = stream.state
    out = [st.depth, st.age, st.evidence, st.mean, st.valid, st.hole, st.confidence, st.spread, st.rgb]
    return out + list(st.matches or ())


def test_to_moves_the_stream_state_with_the_model_and_keeps_its_dtype():
    # the state is no registered buffer: nn.Module.to would leave it on the old device and the next frame would mix
    # devices. "meta" stands for another device; the state keeps the frames' compute dtype (cast where it is read)
    from torch_depth_sr.datasets.synthetic import make_scene

    s = make_scene(24, 32, seed=0)
    stream = StreamRestorer(DepthRestorer(num_layers=2))
    stream.step(s["gt"] + torch.randn_like(s["gt"]), s["rgb"])
    before = [(t.dtype, t.shape) for t in _state_tensors(stream)]
    assert stream.state.matches is not None and {t.device.type for t in _state_tensors(stream)} == {"cpu"}
    stream.double()  # a dtype change: the model's, not the state's
    assert [(t.dtype, t.shape) for t in _state_tensors(stream)] == before
    assert stream.step(s["gt"] + torch.randn_like(s["gt"]), s["rgb"]).shape == (1, 24, 32)
    assert stream.frames == 2
    stream.to("meta")
    assert {t.device.type for t in _state_tensors(stream)} == {"meta"}
    assert {p.device.type for p in stream.parameters()} == {"meta"}
    assert [(t.dtype, t.shape) for t in _state_tensors(stream)] == before


def test_stream_track_seeds_run_the_recipes_on_other_scenes(tmp_path):
    """``bench --track stream --seeds``: the three recipes with the given seeds instead of the evaluated sequences."""
    import json

    from torch_depth_sr.cli import main
    from torch_depth_sr.datasets.sequences import recipe_sequences

    specs = recipe_sequences([7])
    assert [s.seed for s in specs] == [7, 7, 7] and [s.name.split("@")[0] for s in specs] == [
        "static-2movers", "pan-then-hold", "static-busy"]
    out = tmp_path / "s.json"
    assert main(["bench", "--track", "stream", "--sets", "synthetic", "--seeds", "7", "--methods", "raw",
                 "--frames", "3", "--size", "24x32", "--json", str(out)]) == 0
    got = json.loads(out.read_text())
    assert got["metadata"]["seeds"] == [7]
    assert sorted({r["sequence"] for r in got["results"]}) == sorted(s.name for s in specs)


def test_the_singular_gate_also_reads_the_pixels_measured_in_the_frame_alone(monkeypatch):
    """A stream frame's singular gate is given the pixels whose measurement is not a run's mean (``gate_region``):
    a run's mean hides the past's flying pixels, and counted with the rest it diluted a mover's below the gate
    (stages._gate; its own tests in test_singular_gate.py). A frame with no past has no region."""
    import torch_depth_sr.stages as stages

    seen = []
    forward = stages.SingularDetector.forward

    def spy(self, obs, x, matches, held=None):
        seen.append(None if obs.gate_region is None else obs.gate_region.clone())
        return forward(self, obs, x, matches, held)

    monkeypatch.setattr(stages.SingularDetector, "forward", spy)
    gt, rgb = _scene()
    s = StreamRestorer(small_model())
    s.step(_noisy(gt, 0), rgb.transpose(1, 2, 0))
    assert seen and all(r is None for r in seen)
    seen.clear()
    moved = gt.copy()
    moved[10:20, 5:15] = 700  # a near object arrives: measured afresh there
    r = s.step(_noisy(moved, 1), rgb.transpose(1, 2, 0), return_details=True)
    region = seen[0][0, 0]
    assert all(torch.equal(g, seen[0]) for g in seen)  # x⁰'s test and every layer's
    assert bool(region[12:18, 7:13].all())  # the arrival: this frame's own measurements
    static = torch.from_numpy(np.asarray(r.static) > 0) & torch.from_numpy(_noisy(moved, 1) > 0)
    assert float((~region & static).float().mean()) > 0.5  # most of the still scene is a run's mean
