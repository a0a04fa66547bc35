"""The typed settings groups of RestorerConfig (issue 10 item 2) and the operator the layers receive (item 1)."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest
import torch

import torch_depth_sr
from torch_depth_sr import DepthRestorer, ParameterError, RestorerConfig
from torch_depth_sr.config import (BlockMatchingConfig, InitConfig, LayerConfig, SidedFillConfig, SingularConfig,
                                   SolverConfig, UpsamplingConfig, ValuePriorConfig)
from torch_depth_sr.layers import RestorationContext
from torch_depth_sr.operators import AreaDownsample, BicubicDownsample, Identity

GROUPS = ("layer", "block_matching", "value_prior", "singular", "solver", "initial", "upsampling", "edge_snap", "refiner")
TOP_LEVEL = {"num_layers", "fidelity_band", "extra"}
PRETRAINED = sorted((Path(torch_depth_sr.__file__).parent / "pretrained").glob("*/config.json"))


def _flat_fields(group) -> set:
    return set(group.to_flat())


def test_every_field_belongs_to_exactly_one_group():
    c = RestorerConfig()
    owners: dict = {}
    for g in GROUPS:
        for f in _flat_fields(getattr(c, g)):
            owners.setdefault(f, []).append(g)
    assert {f: gs for f, gs in owners.items() if len(gs) > 1} == {}
    fields = {f.name for f in dataclasses.fields(RestorerConfig)}
    assert set(owners) == fields - TOP_LEVEL, sorted(fields - TOP_LEVEL ^ set(owners))


@pytest.mark.parametrize("group", GROUPS)
def test_group_puts_back_what_it_read(group):
    c = RestorerConfig(singular_rounds=2, cg_fixed_iters=(3, 1), upsample_jbu={"radius": 3},
                       upsample_scale={"lam": 2.0}, init_fill="jbf", nl_value_ridge=0.5, k=7)
    g = getattr(c, group)
    assert dataclasses.is_dataclass(g) and g.__dataclass_params__.frozen
    back = c.replace(**g.to_flat())
    assert getattr(back, group) == g
    if group != "upsampling":  # the dicts come back with every key (the same values)
        assert back == c


def test_with_groups_writes_a_group_back_and_checks_it():
    c = RestorerConfig()
    d = c.with_groups(dataclasses.replace(c.singular, rounds=1), dataclasses.replace(c.solver, tol=1e-2))
    assert (d.singular_rounds, d.cg_tol) == (1, 1e-2) and d.replace(singular_rounds=3, cg_tol=1e-3) == c
    with pytest.raises(ParameterError, match="singular_rounds"):
        c.with_groups(dataclasses.replace(c.singular, rounds=0))
    with pytest.raises(ParameterError, match="group"):
        c.with_groups({"singular_rounds": 1})


def test_groups_read_the_flat_fields():
    c = RestorerConfig(singular_tau=0.4, cg_tol=1e-4, cg_fixed_iters=(), nl_value_weight=0.0, rematch="exact",
                       init_dt_iterations=2, upsample_scale={"mu1": 2.0}, degradation="bicubic", lam=0.7)
    assert isinstance(c.singular, SingularConfig) and c.singular.tau == 0.4
    assert isinstance(c.solver, SolverConfig) and c.solver.tol == 1e-4 and c.solver.iterations(3) is None
    assert isinstance(c.value_prior, ValuePriorConfig) and c.value_prior.weight == 0.0
    assert isinstance(c.block_matching, BlockMatchingConfig) and c.block_matching.rematch == "exact"
    assert isinstance(c.initial, InitConfig) and c.initial.dt_iterations == 2
    assert isinstance(c.layer, LayerConfig) and c.layer.lam == 0.7
    up = c.upsampling
    assert isinstance(up, UpsamplingConfig) and up.degradation == "bicubic"
    assert (up.multipliers.mu1, up.multipliers.mu2, up.multipliers.lam) == (2.0, 1.0, 1.0)
    assert RestorerConfig().solver.iterations(100) == RestorerConfig().cg_fixed_iters[-1]


def test_sided_fill_group_from_extra():
    assert RestorerConfig().initial.sided_fill == SidedFillConfig()
    assert RestorerConfig(extra={"sided_fill": False}).initial.sided_fill is None
    assert RestorerConfig(init_fill="pushpull").initial.sided_fill is None
    c = RestorerConfig(extra={"sided_fill_params": {"gap": 6.0, "quantiles": (0.2, 0.8)}})
    assert c.initial.sided_fill.gap == 6.0
    assert c.initial.sided_fill.fill_arguments()["quantiles"] == (0.2, 0.8)
    with pytest.raises(ParameterError, match="sided_fill_params"):
        RestorerConfig(extra={"sided_fill_params": {"kernel_size": 5}}).initial


def test_layer_weight_policy_under_upsampling():
    up = RestorerConfig(upsample_scale={"mu1": 3.0, "lam": 2.0}).upsampling
    w = tuple(torch.tensor(v) for v in (1.0, 2.0, 3.0, 4.0, 5.0))
    assert up.layer_weights(Identity(), *w) == w
    lam, eta, gamma, mu1, mu2 = up.layer_weights(AreaDownsample(4), *w)
    assert [float(v) for v in (lam, eta, gamma, mu1, mu2)] == [0.5, 2.0, 3.0, 12.0, 5.0]
    flat = RestorerConfig(upsample_tv_per_factor=False).upsampling
    assert float(flat.layer_weights(BicubicDownsample(2), *w)[0]) == 1.0


@pytest.mark.parametrize("path", PRETRAINED, ids=lambda p: p.parent.name)
def test_shipped_flat_configs_build_every_group(path):
    c = RestorerConfig.from_dict(json.loads(path.read_text()))
    for g in GROUPS:
        getattr(c, g)
    model = DepthRestorer.from_pretrained(path.parent.name)
    assert model.layers[0].singular_detector.settings == c.singular
    assert model.initializer.settings == c.initial


def test_context_carries_the_operator_not_a_factor():
    names = {f.name for f in dataclasses.fields(RestorationContext)}
    assert "K" in names and not names & {"factor", "config", "degradation"}


@pytest.mark.parametrize("degradation, factor, expected", [
    ("area", 1, Identity()), ("bicubic", 1, Identity()), ("area", 2, AreaDownsample(2)),
    ("bicubic", 4, BicubicDownsample(4)),
])
def test_every_layer_receives_the_task_operator(scene, degradation, factor, expected):
    model = DepthRestorer(num_layers=2, search_window=7, k=4, degradation=degradation)
    seen = []
    for layer in model.layers:
        layer.register_forward_pre_hook(lambda mod, args: seen.append(args[1].K))
    depth = scene["depth"][..., ::factor, ::factor] if factor > 1 else scene["depth"]
    model(depth, scene["rgb"])
    assert len(seen) == 2 and all(repr(K) == repr(expected) for K in seen)
    assert seen[0] is seen[1]  # built once per forward
