"""The stages own their settings groups and the layer's state holds the iterates only (issue 10 item 2)."""
from __future__ import annotations

import dataclasses

import pytest
import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.initial import Initializer
from torch_depth_sr.stages import BlockMatcher, LinearSolver, SingularDetector
from torch_depth_sr.state import RestorationContext, RestorationState, RunLog

SMALL = dict(num_layers=3, search_window=9, k=4)


def test_state_holds_the_iterates_only():
    names = [f.name for f in dataclasses.fields(RestorationState)]
    assert names == ["x", "z", "w", "e", "alpha", "q", "confidence", "matches"]


def test_the_run_log_lives_in_the_context():
    fields = {f.name: f for f in dataclasses.fields(RestorationContext)}
    assert "log" in fields and not {"cg_iterations", "timings"} & set(fields)
    assert [f.name for f in dataclasses.fields(RunLog)] == ["cg_iterations", "timings"]
    a, b = RunLog(), RunLog()
    assert a.cg_iterations is not b.cg_iterations and a.timings is None  # one log per forward, untimed by default


def test_every_stage_holds_its_group():
    model = DepthRestorer(**SMALL, rematch="exact", singular_tau=0.4, cg_fixed_iters=(4, 2), init_fill="jbf")
    c = model.config
    assert isinstance(model.initializer, Initializer)
    assert model.initializer.settings == c.initial and model.initializer.upsampling == c.upsampling
    assert model.block_matcher.settings == c.block_matching and model.singular_detector.settings == c.singular
    assert isinstance(model.block_matcher, BlockMatcher)
    for layer in model.layers:
        assert not hasattr(layer, "block_matcher")  # one matcher, the model's: it owns h, shared by every layer
        assert isinstance(layer.singular_detector, SingularDetector) and layer.singular_detector.settings == c.singular
        assert isinstance(layer.linear_solver, LinearSolver) and layer.linear_solver.settings == c.solver
        assert layer.terms == c.layer and layer.value_prior == c.value_prior and layer.upsampling == c.upsampling
    # the overrides reached the groups the stages hold
    assert model.block_matcher.settings.rematch == "exact"
    assert model.layers[1].singular_detector.settings.tau == 0.4
    assert model.layers[2].linear_solver.settings.fixed_iters == (4, 2)
    assert model.initializer.settings.fill == "jbf"


def test_only_the_block_matcher_holds_state():
    keys = set(DepthRestorer(**SMALL).state_dict())
    assert keys == {"block_matcher.log_temperature", "block_matcher.log_color_weight"} | {
        f"layers.{i}.raw_{n}" for i in range(SMALL["num_layers"]) for n in ("lam", "eta", "gamma", "mu1", "mu2")}


def test_the_layer_runs_the_settings_its_stage_holds(scene):
    """A stage swapped for one with other settings changes the forward: the layer reads them from the stage."""
    model = DepthRestorer(**SMALL, cg_fixed_iters=(5,))
    base = model.restore_with_details(scene["depth"], scene["rgb"]).info["cg_iterations"]
    solver = model.layers[0].linear_solver
    model.layers[0].linear_solver = LinearSolver(dataclasses.replace(solver.settings, fixed_iters=(1,)))
    swapped = model.restore_with_details(scene["depth"], scene["rgb"]).info["cg_iterations"]
    assert base[0] > 1 and swapped[0] == 1


@pytest.mark.parametrize("timed", [False, True])
def test_stages_record_into_the_run_log(scene, timed):
    """Each stage appends to the context's log; the stage times appear in ``info["seconds"]`` only when asked."""
    model = DepthRestorer(**SMALL)
    calls = []
    hooked = {"block_matcher": model.block_matcher, "singular_detector": model.layers[0].singular_detector}
    for name, module in hooked.items():
        module.register_forward_hook(lambda mod, args, out, n=name: calls.append(n))
    info = model.restore_with_details(scene["depth"], scene["rgb"], timings=timed).info
    assert len(info["cg_iterations"]) == SMALL["num_layers"]
    assert "singular_detector" in calls
    # x⁰'s matches and those of each scheduled layer go through the model's one matcher
    assert calls.count("block_matcher") == 1 + sum(i in model.config.match_layers for i in range(SMALL["num_layers"]))
    if timed:
        assert {"block_matching", "singular", "cg", "total"} <= set(info["seconds"])
    else:
        assert info["seconds"] == {}
