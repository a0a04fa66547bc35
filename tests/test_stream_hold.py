"""A stream's held outputs (StreamConfig.hold, stream/post_hold.py): while the edge steps act, a steady pixel keeps its
previous output and the post-steps skip it; a change the change test does not see still reaches the output; the edge
snap computes only the pixels it may move. The scenes here have no flying pixels, so the singular gate leaves the
edge steps off; the tests of the holding itself switch them on (``edges_on``)."""
import numpy as np
import pytest
import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.edge_snap import snap_to_sides
from torch_depth_sr.stream import StreamRestorer

H, W = 40, 48


def _scene():
    """Two slanted planes of different colour and depth (mm), a depth gap at the middle column."""
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    gt = np.where(xx < W // 2, 1000 + 2 * yy, 1600 + xx).astype(np.float32)
    rgb = np.zeros((3, H, W), np.float32)
    rgb[:, :, : W // 2] = np.array([0.8, 0.3, 0.2], np.float32)[:, None, None]
    rgb[:, :, W // 2:] = np.array([0.2, 0.4, 0.8], np.float32)[:, None, None]
    rgb += 0.05 * np.sin(xx / 3)[None]
    return gt, rgb


def _noisy(gt: np.ndarray, t: int, sigma: float = 6.0) -> np.ndarray:
    rng = np.random.default_rng(2000 + t)
    d = np.round(gt + sigma * rng.standard_normal(gt.shape))
    d[rng.random(gt.shape) < 0.03] = 0
    return d.astype(np.uint16)


@pytest.fixture
def edges_on(monkeypatch):
    """The stream takes the edge steps to act on every frame, as the gate makes them on sensor input."""
    from torch_depth_sr.stream import frame as frame_module

    monkeypatch.setattr(frame_module, "_edges_on",
                        lambda state, like: torch.ones(like.shape[0], 1, 1, 1, dtype=torch.bool))


def _model() -> DepthRestorer:
    return DepthRestorer.from_pretrained("denoise-fast")  # the stream's model: its post-steps, its `layers`


def _run(settings: dict, frames: list, rgb: np.ndarray) -> tuple[list, list]:
    s = StreamRestorer(_model(), {"max_frames": 3, **settings})
    outs, infos = [], []
    for d in frames:
        r = s.step(d, rgb, return_details=True)
        outs.append(np.asarray(r.depth, np.float64))
        infos.append(r.info["stream"])
    return outs, infos


def test_a_static_scene_holds_its_steady_pixels_and_flickers_less(edges_on):
    gt, rgb = _scene()
    frames = [_noisy(gt, t) for t in range(10)]
    held, info_h = _run({}, frames, rgb)
    every, info_e = _run({"hold": None}, frames, rgb)
    assert "held" not in info_e[-1] and "held" not in info_h[0]  # a first frame holds nothing
    assert info_h[-1]["held"] > 0.5  # most of a still scene
    same = np.mean(held[-1] == held[-2])
    assert same >= info_h[-1]["held"] - 0.01  # the held pixels' outputs are the previous frame's
    assert np.std(np.stack(held[5:]), 0).mean() < np.std(np.stack(every[5:]), 0).mean()
    for a, b in zip(held, every):  # the output stays as accurate
        assert np.sqrt(np.mean((a - gt) ** 2)) < np.sqrt(np.mean((b - gt) ** 2)) + 0.5


def test_a_change_below_the_change_test_still_reaches_the_output(edges_on):
    """A surface that creeps by 0.5 σ a frame is static to the change test; the layers' value follows the runs' mean,
    and once it has moved by ``hold`` units the pixel is no longer held."""
    gt, rgb = _scene()
    frames = [_noisy(gt, t) for t in range(6)]
    frames += [_noisy(gt + np.where(np.arange(W) < W // 2, 3.0 * (t + 1), 0.0)[None, :], 6 + t) for t in range(14)]
    held, info = _run({}, frames, rgb)
    every, _ = _run({"hold": None}, frames, rgb)
    left = (slice(5, H - 5), slice(3, W // 2 - 5))
    moved = held[-1][left].mean() - held[5][left].mean()
    assert moved > 0.8 * (every[-1][left].mean() - every[5][left].mean())
    assert abs(held[-1][left].mean() - every[-1][left].mean()) < 3.0


def test_nothing_is_held_while_training(edges_on):
    """With a gradient tracked, every pixel gets the post-steps (a held output would carry none): the frame is what
    the same stream makes without ``hold``, and the loss of a still pixel reaches the parameters."""
    import copy

    gt, rgb = _scene()
    c = torch.from_numpy(rgb)[None]
    frames = [torch.from_numpy(_noisy(gt, t).astype(np.float32))[None, None] for t in range(7)]
    model = DepthRestorer.from_pretrained("denoise-fast", trainable=True)
    held = StreamRestorer(model, {"max_frames": 3})
    with torch.no_grad():
        for f in frames[:6]:
            r = held.step(f, c, return_details=True)
    assert r.info["stream"]["held"] > 0.5  # without a gradient, held
    every = copy.deepcopy(held)
    every.settings = every.settings.replace(hold=None)
    out = held(frames[6], c)
    assert torch.equal(out, every(frames[6], c))
    out[..., 5, 5].sum().backward()  # one still pixel of the left plane
    assert any(float(p.grad.abs().sum()) > 0 for p in model.parameters() if p.grad is not None)


def test_the_hold_setting_is_checked():
    from torch_depth_sr.config import RestorerConfig

    with pytest.raises(Exception, match="stream.hold"):
        RestorerConfig(stream={"hold": -1.0})


def test_the_edge_snap_with_a_per_pixel_mask_moves_what_the_whole_frame_moves_there():
    """On the CPU a per-pixel ``active`` computes only those windows: the same values as every window, kept there."""
    g = torch.Generator().manual_seed(3)
    x = torch.full((2, 1, 24, 30), 10.0)
    x[..., 15:] = 50.0
    x[..., 14] = 30.0  # a blend between the sides
    x = x + torch.randn(x.shape, generator=g)
    rgb = torch.zeros(2, 3, 24, 30)
    rgb[..., 15:] = 1.0
    rgb[..., 14] = 0.9
    active = torch.rand(2, 1, 24, 30, generator=g) < 0.4
    sparse = snap_to_sides(x, rgb, rounds=1, active=active)
    dense = snap_to_sides(x, rgb, rounds=1)
    assert torch.equal(sparse, torch.where(active, dense, x))
    assert not torch.equal(dense, x)  # something moved


def test_outputs_are_held_only_while_the_edge_steps_act(monkeypatch):
    """The edge steps act on the samples the singular gate finds outliers in. While they do not (a clean still scene
    here) a held output would save nothing and only miss what the runs' means still add: nothing is held. An output
    computed while they did not act is not held once they do (a mover's flying pixels switch them on for the whole
    frame): that frame computes every pixel, and the next holds."""
    from torch_depth_sr.stream import frame as frame_module

    gt, rgb = _scene()
    on = {"edges": False}
    real = frame_module._edges_on
    monkeypatch.setattr(frame_module, "_edges_on",
                        lambda state, like: real(state, like) | torch.tensor(on["edges"], device=like.device))
    s = StreamRestorer(_model(), {"max_frames": 3})
    held = []
    for t in range(9):
        on["edges"] = t >= 6
        held.append(s.step(_noisy(gt, t), rgb, return_details=True).info["stream"].get("held"))
    assert held[1:6] == [0.0] * 5  # the gate found this scene clean: nothing held
    assert held[6] == 0.0  # the verdict changed: nothing held
    assert held[8] > 0.5
