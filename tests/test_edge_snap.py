"""Edge snapping (torch_depth_sr/edge_snap.py): blends and flying pixels go to the side their colour names, nothing
else moves; the model snaps only samples in which the singular test's gate found outliers."""
import json
from pathlib import Path

import pytest
import torch

import torch_depth_sr
from torch_depth_sr import DepthRestorer, RestorerConfig
from torch_depth_sr.config import EdgeRefit, EdgeSnap, load_config_file
from torch_depth_sr.datasets.synthetic import make_scene
from torch_depth_sr.edge_snap import refit_to_measurements, sided_median, snap_to_sides
from torch_depth_sr.errors import ParameterError
from torch_depth_sr.evaluation import SensorDegradation
from torch_depth_sr.metrics import evaluate
from torch_depth_sr.post_steps import EdgeRefitStep, EdgeSnapStep


def _step_edge(h=12, w=12, near=10.0, far=50.0):
    """A vertical depth edge at column w//2 whose colour edge is at the same place."""
    depth = torch.full((1, 1, h, w), far)
    depth[..., : w // 2] = near
    rgb = torch.zeros(1, 3, h, w)
    rgb[:, :, :, : w // 2] = torch.tensor([0.9, 0.2, 0.1]).view(1, 3, 1, 1)
    rgb[:, :, :, w // 2:] = torch.tensor([0.1, 0.3, 0.8]).view(1, 3, 1, 1)
    return depth, rgb


def test_median_is_a_value_of_the_window_and_share_is_a_fraction():
    g = torch.Generator().manual_seed(0)
    x = torch.rand(2, 1, 9, 11, generator=g) * 100
    rgb = torch.rand(2, 3, 9, 11, generator=g)
    m, share = sided_median(x, rgb, radius=2)
    assert ((share >= 0) & (share <= 1)).all()
    # every median is one of the 25 values of its window (zero padding outside does not vote)
    pad = torch.nn.functional.pad(x, (2, 2, 2, 2), value=float("nan"))
    win = torch.nn.functional.unfold(pad, 5).view(2, 25, 9, 11)
    assert ((win - m).abs() < 1e-6).any(1).all()


def test_batch_equals_one_by_one():
    g = torch.Generator().manual_seed(1)
    x = torch.rand(3, 1, 10, 8, generator=g) * 30
    rgb = torch.rand(3, 3, 10, 8, generator=g)
    batched = snap_to_sides(x, rgb, rounds=2)
    single = torch.cat([snap_to_sides(x[i:i + 1], rgb[i:i + 1], rounds=2) for i in range(3)])
    assert torch.equal(batched, single)


def test_flying_pixels_go_to_the_side_of_their_colour():
    depth, rgb = _step_edge()
    noisy = depth.clone()
    noisy[0, 0, 3, 5] = 25.0   # a flying pixel on the near (left) side's colour
    noisy[0, 0, 7, 6] = 37.0   # and one on the far side's colour
    before = noisy.clone()
    out = snap_to_sides(noisy, rgb, rounds=1)
    assert torch.equal(noisy, before)  # the input is not modified
    assert out[0, 0, 3, 5] == 10.0 and out[0, 0, 7, 6] == 50.0
    assert torch.equal(out[noisy == depth], depth[noisy == depth])  # nothing else moved


def test_a_blend_without_a_colour_majority_stays():
    """Same colour on both sides of the edge: nothing says which side a blend belongs to, so it keeps its value
    (the squared error of a wrong side is four times the blend's)."""
    depth, _ = _step_edge()
    rgb = torch.full((1, 3, 12, 12), 0.5)
    blended = depth.clone()
    blended[..., 6] = 30.0  # a blend column between 10 and 50
    assert torch.equal(snap_to_sides(blended, rgb, rounds=2), blended)


def test_smooth_surfaces_do_not_move():
    """A slanted plane under uniform colour and a noisy plane under random texture: the median sits on the pixel's
    own value or on both sides evenly, never a clear majority on one side."""
    yy, xx = torch.meshgrid(torch.arange(16.0), torch.arange(16.0), indexing="ij")
    ramp = (20 + 1.5 * xx + 0.5 * yy).view(1, 1, 16, 16)
    assert torch.equal(snap_to_sides(ramp, torch.full((1, 3, 16, 16), 0.4), rounds=2), ramp)


def test_gradient_flows_through_the_selected_values():
    depth, rgb = _step_edge()
    x = depth.clone()
    x[0, 0, 3, 5] = 25.0
    x.requires_grad_(True)
    snap_to_sides(x, rgb, rounds=1).sum().backward()
    assert torch.isfinite(x.grad).all() and x.grad.sum() == pytest.approx(x.numel())


@pytest.mark.parametrize("group,field,value", [
    ("edge_snap", "share", 1.0), ("edge_snap", "share", 0.4), ("edge_snap", "radius", 0), ("edge_snap", "rounds", -1),
    ("edge_snap", "rounds", 0), ("edge_snap", "sigma_color", 0.0), ("edge_refit", "sigma_color", 0.0),
    ("edge_refit", "radius", -1), ("edge_refit", "band", 0.0)])
def test_settings_out_of_range_are_refused(group, field, value):
    with pytest.raises(ParameterError, match=f"{group}.{field}"):
        RestorerConfig().replace(**{group: {field: value}})


def test_model_snaps_sensor_input():
    s = make_scene(64, 64, seed=3)
    d = SensorDegradation(seed=0)({**s, "mask": torch.ones_like(s["gt"]), "name": "synthetic-3"})
    y, rgb = d["depth"].clamp_min(0)[None], s["rgb"][None]
    with torch.no_grad():
        snapped = DepthRestorer(num_layers=3)(y, rgb)
        kept = DepthRestorer(num_layers=3, edge_snap=None, edge_refit=None)(y, rgb)
    sample = {**d, "depth": y[0]}
    assert evaluate(snapped, sample)["flying_left"] < evaluate(kept, sample)["flying_left"]


def test_on_clean_maps_trusted_pixels_stay_and_the_rest_is_not_worse():
    """Float clean maps (no grid, so the gate sees the singular test's false alarms at edges and snapping acts):
    the fidelity band after the snap keeps every trusted pixel at its measurement, and over six scenes the
    untrusted ones end closer to the truth than without snapping."""
    errors = {0: [], 1: []}
    for seed in range(6):
        s = make_scene(64, 64, seed=seed)
        clean, rgb = s["gt"][None], s["rgb"][None]
        for rounds in (0, 1):  # 0: neither snapping nor the refit; 1: the defaults
            off = {} if rounds else {"edge_snap": None, "edge_refit": None}
            with torch.no_grad():
                r = DepthRestorer(num_layers=3, **off).restore_with_details(clean, rgb)
            trusted = r.trusted > 0
            assert (r.depth - clean)[trusted].abs().max() < 1e-3
            errors[rounds].append(float((r.depth - clean).pow(2).mean().sqrt()))
    assert sum(errors[1]) < sum(errors[0])


def test_refit_takes_the_side_measurements_near_edges_and_nothing_elsewhere():
    depth, rgb = _step_edge(16, 16)
    g = torch.Generator().manual_seed(2)
    y = depth + 0.5 * torch.randn(depth.shape, generator=g)
    pulled = depth.clone()
    pulled[..., 7] = 14.0   # the near side's last column, pulled towards the far side
    pulled[..., 8] = 46.0   # and the far side's first column
    pulled[..., 1:3] = 10.3  # a flat region far from the edge: left alone whatever its value
    before = pulled.clone()
    out = refit_to_measurements(pulled, y, torch.ones_like(y), rgb, radius=3, band=5.0, edge=20.0)
    assert torch.equal(pulled, before)
    assert (out[..., 7] - 10.0).abs().max() < 1.0 and (out[..., 8] - 50.0).abs().max() < 1.0
    assert torch.equal(out[..., :3], pulled[..., :3])
    # each new value is one of the measurements
    assert all(bool((y == v).any()) for v in out[..., 7:9].flatten())
    # no measurement within the band, or the sample switched off: nothing moves
    assert torch.equal(refit_to_measurements(pulled, y, torch.zeros_like(y), rgb, radius=3, band=5.0, edge=20.0),
                       pulled)
    off = torch.zeros(1, 1, 1, 1, dtype=torch.bool)
    assert torch.equal(refit_to_measurements(pulled, y, torch.ones_like(y), rgb, radius=3, band=5.0, edge=20.0,
                                             active=off), pulled)


def test_shipped_models_can_be_loaded_without_the_edge_steps():
    from torch_depth_sr.errors import ParameterError as PE

    model = DepthRestorer.from_pretrained("denoise", edge_snap=None, edge_refit=None)
    assert model.config.edge_snap is None and model.config.edge_refit is None
    assert not [s for s in model.post["denoise"] if isinstance(s, (EdgeSnapStep, EdgeRefitStep))]
    with pytest.raises(PE, match="edge_snap.rounds"):
        DepthRestorer.from_pretrained("denoise", edge_snap={"rounds": -1})
    with pytest.raises(PE, match="no_such_field"):
        DepthRestorer.from_pretrained("denoise", no_such_field=1)


def test_the_denoiser_keeps_the_edge_steps_of_its_version1_file(version1_model):
    """The shipped denoiser's version-1 file named no edge-step setting: it converts with version 1's (snapping and
    the refit on), and the shipped file, saved since, writes them."""
    folder = version1_model("denoise")
    assert not [k for k in json.loads((folder / "config.json").read_text()) if k.startswith("snap_")]
    model = DepthRestorer.load(folder)
    assert model.config.edge_snap == EdgeSnap(rounds=1, radius=2, share=0.6, sigma_color=0.235, sigma_space=None)
    assert model.config.edge_refit == EdgeRefit(radius=5, band=1.5, edge=2.0, sigma_color=0.235)
    assert [type(s) for s in model.post["denoise"]][:2] == [EdgeSnapStep, EdgeRefitStep]
    shipped = Path(torch_depth_sr.__file__).parent / "pretrained" / "denoise" / "config.json"
    written = json.loads(shipped.read_text())
    assert written["edge_snap"] == model.config.edge_snap.to_dict()
    assert written["edge_refit"] == model.config.edge_refit.to_dict()
    assert load_config_file(shipped) == model.config
