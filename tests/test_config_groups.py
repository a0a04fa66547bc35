"""The settings groups of RestorerConfig (issue 10 item 2, issue 26: version 2), the conversion of version-1 files
and the operator the layers receive (issue 10 item 1)."""
from __future__ import annotations

import dataclasses
import json
import types
import typing
from pathlib import Path

import pytest
import torch

import torch_depth_sr
from torch_depth_sr import DepthRestorer, ParameterError, RestorerConfig
from torch_depth_sr.config import (BlockMatchingConfig, EdgeRefit, EdgeSnap, InitConfig, LayerWeights, OutputHold,
                                   SidedFill, SingularConfig, SolverConfig, UpsamplingConfig, load_config_file)
from torch_depth_sr.config.groups import Group
from torch_depth_sr.config.version1 import FLAT_FIELDS, VERSION1_DEFAULTS
from torch_depth_sr.layers import UnrolledLayer
from torch_depth_sr.operators import AreaDownsample, BicubicDownsample, Identity
from torch_depth_sr.terms import SingularTest


def _group_type(hint):
    """The settings group a field holds (``Optional[G]``: G), or None for a plain value."""
    kinds = [t for t in (hint, *typing.get_args(hint)) if isinstance(t, type) and issubclass(t, Group)]
    return kinds[0] if kinds else None


GROUPS = tuple(name for name, hint in typing.get_type_hints(RestorerConfig).items()
               if name in {f.name for f in dataclasses.fields(RestorerConfig)} and _group_type(hint))
PRETRAINED = sorted((Path(torch_depth_sr.__file__).parent / "pretrained").glob("*/config.json"))
# every group on, so that each is compared field by field
ALL_ON = RestorerConfig().replace(guidance={}, refiner={}, stream={})


def _changed(name: str, v):
    """A version-1 value of ``name`` in its domain other than the version-1 default ``v``."""
    special = {"singular_tau": 0.25, "singular_gate": 0.001, "snap_share": 0.7, "guidance_range": 8.0,
               "snap_sigma_space": 1.0, "init_fill": "jbf", "upsample_init": "bicubic", "degradation": "bicubic",
               "rematch": "exact", "refine_task": "denoise", "match_layers": (3,), "cg_fixed_iters": (2,),
               "upsample_jbu": {"radius": 3}, "upsample_scale": {"mu1": 2.0}, "extra": {"sided_fill": False}}
    if name in special:
        return special[name]
    if isinstance(v, bool):
        return not v
    if isinstance(v, int):
        return v + 2 if name in ("block_size", "search_window", "upsample_search_window") else v + 1
    return v / 2


@pytest.mark.parametrize("name", sorted(FLAT_FIELDS))
def test_every_version1_field_reaches_the_groups(name):
    """No version-1 setting is lost in the conversion: each one, changed, changes the version-2 config."""
    base = {"guidance_net": True, "refine_net": True}  # their settings count only when they are on
    value = _changed(name, {**VERSION1_DEFAULTS, **base}[name])
    assert RestorerConfig.from_dict({**base, name: value}) != RestorerConfig.from_dict(base), (name, value)


@pytest.mark.parametrize("group", GROUPS)
def test_group_puts_back_what_it_read(group):
    c = ALL_ON.replace(singular={"rounds": 2}, solver={"fixed_iters": (3, 1)},
                       upsampling={"jbu": {"radius": 3}, "multipliers": {"lam": 2.0}}, initial={"fill": "jbf"},
                       value_prior={"ridge": 0.5}, block_matching={"k": 7})
    g = getattr(c, group)
    assert dataclasses.is_dataclass(g) and g.__dataclass_params__.frozen
    assert ALL_ON.replace(**{group: g}) == ALL_ON.replace(**{group: g.to_dict()})  # a group, or a dict of it
    assert getattr(ALL_ON.replace(**{group: g}), group) == g
    assert type(g).from_dict(json.loads(json.dumps(g.to_dict()))) == g  # JSON (lists for tuples) and back
    assert RestorerConfig.from_dict(json.loads(c.to_json())) == c


def test_a_replaced_group_is_checked():
    c = RestorerConfig()
    d = c.replace(singular=dataclasses.replace(c.singular, rounds=1), solver=dataclasses.replace(c.solver, tol=1e-2))
    assert (d.singular.rounds, d.solver.tol) == (1, 1e-2)
    assert d.replace(singular={"rounds": 3}, solver={"tol": 1e-3}) == c
    with pytest.raises(ParameterError, match="singular.rounds"):
        c.replace(singular=dataclasses.replace(c.singular, rounds=0))
    with pytest.raises(ParameterError, match="singular.rounds"):
        c.replace(singular={"rounds": 0})
    with pytest.raises(ParameterError, match="singular"):
        c.replace(singular=SolverConfig())  # a group of another kind
    with pytest.raises(ParameterError, match="singular"):
        c.replace(singular=None)  # not a step that may be off
    with pytest.raises(ParameterError, match="singular_rounds"):
        c.replace(singular_rounds=1)  # the version-1 names are gone


def test_groups_read_the_version1_flat_fields():
    c = RestorerConfig.from_dict(dict(singular_tau=0.4, cg_tol=1e-4, cg_fixed_iters=(), nl_value_weight=0.0,
                                      rematch="exact", init_dt_iterations=2, upsample_scale={"mu1": 2.0},
                                      degradation="bicubic", lam=0.7))
    assert isinstance(c.singular, SingularConfig) and c.singular.tau == 0.4
    assert isinstance(c.solver, SolverConfig) and c.solver.tol == 1e-4 and c.solver.iterations(3) is None
    assert c.value_prior is None  # version 1 switched it off with weight 0
    assert isinstance(c.block_matching, BlockMatchingConfig) and c.block_matching.rematch == "exact"
    assert isinstance(c.initial, InitConfig) and c.initial.dt_iterations == 2
    assert isinstance(c.weights, LayerWeights) and c.weights.lam == 0.7
    up = c.upsampling
    assert isinstance(up, UpsamplingConfig) and c.degradation == "bicubic"
    # version 1's upsample_scale named only the multipliers other than 1
    assert (up.multipliers.mu1, up.multipliers.mu2, up.multipliers.lam) == (2.0, 1.0, 1.0)
    assert RestorerConfig().solver.iterations(100) == RestorerConfig().solver.fixed_iters[-1]


def test_sided_fill_group_and_its_version1_form():
    assert RestorerConfig().sided_fill == SidedFill()
    assert RestorerConfig().replace(sided_fill=None).sided_fill is None
    c = RestorerConfig().replace(sided_fill={"gap": 6.0, "quantiles": (0.2, 0.8)})
    assert c.sided_fill.gap == 6.0 and c.sided_fill.fill_arguments()["quantiles"] == (0.2, 0.8)
    # version 1: config.extra, and no sided fill with push-pull
    assert RestorerConfig.from_dict({"extra": {}}).sided_fill == SidedFill()
    assert RestorerConfig.from_dict({"extra": {"sided_fill": False}}).sided_fill is None
    assert RestorerConfig.from_dict({"init_fill": "pushpull"}).sided_fill is None
    c = RestorerConfig.from_dict({"extra": {"sided_fill_params": {"gap": 6.0, "quantiles": [0.2, 0.8]}}})
    assert c.sided_fill.gap == 6.0 and c.sided_fill.fill_arguments()["quantiles"] == (0.2, 0.8)
    with pytest.raises(ParameterError, match="sided_fill"):
        RestorerConfig.from_dict({"extra": {"sided_fill_params": {"kernel_size": 5}}})
    with pytest.raises(ParameterError, match="sided_fill"):
        RestorerConfig().replace(sided_fill={"kernel_size": 5})


def test_layer_weight_policy_under_upsampling():
    config = RestorerConfig(weights=dict(lam=1.0, eta=2.0, gamma=3.0, mu1=4.0, mu2=5.0),
                            upsampling={"multipliers": {"mu1": 3.0, "lam": 2.0, "mu2": 1.0}})
    layer = UnrolledLayer(config, 0)

    def weights(task, K, layer=layer):
        return [float(v) for v in layer.weights(types.SimpleNamespace(task=task, K=K), torch.float64)]

    assert weights("denoise", Identity()) == pytest.approx([1.0, 2.0, 3.0, 4.0, 5.0], rel=1e-6)
    assert weights("upsample", AreaDownsample(4)) == pytest.approx([0.5, 2.0, 3.0, 12.0, 5.0], rel=1e-6)
    flat = UnrolledLayer(config.replace(upsampling={"tv_per_factor": False}), 0)
    assert weights("upsample", BicubicDownsample(2), flat)[0] == pytest.approx(2.0, rel=1e-6)


@pytest.mark.parametrize("path", PRETRAINED, ids=lambda p: p.parent.name)
def test_shipped_configs_build_every_group(path):
    c = load_config_file(path)
    assert RestorerConfig.from_dict(json.loads(c.to_json())) == c
    model = DepthRestorer.from_pretrained(path.parent.name)
    assert model.config == c
    if c.uses("singular"):
        assert model.singular_detector.settings == c.singular
        assert [s.detector.settings for s in model.layers[0].steps["denoise"] if isinstance(s, SingularTest)] == \
            [c.singular]
    assert model.init["denoise"].settings == c.initial and model.init["upsample"].upsampling == c.upsampling
    assert model.block_matcher.settings == c.block_matching and model.layers[0].linear_solver.settings == c.solver


def test_a_version1_file_converts_with_the_version1_defaults_and_save_writes_every_field(version1_model, tmp_path,
                                                                                          scene):
    """The version-1 ``config.json`` the shipped denoiser was trained with names 58 of the 80 fields; those it
    leaves out take the defaults of version 1 (not later ones), and saving writes every setting."""
    folder = version1_model("denoise")
    c = load_config_file(folder / "config.json")
    assert c == DepthRestorer.from_pretrained("denoise").config  # the shipped version-2 file says the same
    # named in the file
    assert (c.block_matching.k, c.block_matching.search_window, c.singular.support_tol) == (10, 21, 3.0)
    assert c.clean_samples.value_weight is None  # nl_value_weight_clean = 0: η₃ as on other samples
    # left out: version 1's defaults
    assert c.edge_snap == EdgeSnap(rounds=1, radius=2, share=0.6, sigma_color=0.235, sigma_space=None)
    assert c.edge_refit == EdgeRefit(radius=5, band=1.5, edge=2.0, sigma_color=0.235)
    assert c.upsample_hold == OutputHold(band=3.0, edge=1.0, edge_threshold=16.0)
    assert (c.upsampling.init_edge_band, c.upsampling.init_consistency) == (0.5, 2.0)
    assert (c.block_matching.upsample_search_window, c.block_matching.upsample_k) == (21, 10)
    assert c.guidance is None and c.refiner is None
    # save writes version 2 with every field of every group; it loads back to the same model
    model = DepthRestorer.load(folder)
    model.save(tmp_path / "v2")
    written = json.loads((tmp_path / "v2" / "config.json").read_text())
    assert written == json.loads(c.to_json()) and written["version"] == RestorerConfig.VERSION
    assert set(written) == {"version"} | {f.name for f in dataclasses.fields(RestorerConfig)}
    for name in GROUPS:
        group = getattr(c, name)
        if group is not None:
            assert set(written[name]) == {f.name for f in dataclasses.fields(group)}, name
    back = DepthRestorer.load(tmp_path / "v2")
    assert back.config == c
    torch.testing.assert_close(back(scene["depth"], scene["rgb"]), model(scene["depth"], scene["rgb"]),
                               rtol=0, atol=0)


@pytest.mark.parametrize("degradation, factor, expected", [
    ("area", 1, Identity()), ("bicubic", 1, Identity()), ("area", 2, AreaDownsample(2)),
    ("bicubic", 4, BicubicDownsample(4)),
])
def test_every_layer_receives_the_task_operator(scene, degradation, factor, expected):
    model = DepthRestorer(num_layers=2, block_matching={"search_window": 7, "k": 4}, degradation=degradation)
    seen = []
    for layer in model.layers:
        layer.register_forward_pre_hook(lambda mod, args: seen.append(args[1].K))
    depth = scene["depth"][..., ::factor, ::factor] if factor > 1 else scene["depth"]
    model(depth, scene["rgb"])
    assert len(seen) == 2 and all(repr(K) == repr(expected) for K in seen)
    assert seen[0] is seen[1]  # built once per forward
