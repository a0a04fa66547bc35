"""The stages own their settings groups and the layer's state holds the iterates only (issue 10 item 2)."""
from __future__ import annotations

import dataclasses

import pytest
import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.initial import DenoiseInit, UpsampleInit
from torch_depth_sr.post_steps import EdgeRefitStep, EdgeSnapStep, FidelityBandStep, OutputHoldStep
from torch_depth_sr.stages import BlockMatcher, LinearSolver, SingularDetector
from torch_depth_sr.state import RunLog
from torch_depth_sr.terms import GuidedPriorTerm, MatchReader, Rematch, SingularTest

SMALL = dict(num_layers=3, block_matching={"search_window": 9, "k": 4})


def _step(layer, kind, task="denoise"):
    """The one step of type ``kind`` that ``layer`` runs for ``task``."""
    found = [s for s in layer.steps[task] if isinstance(s, kind)]
    assert len(found) == 1, (kind, layer.steps[task])
    return found[0]


def test_each_forward_gets_its_own_run_log():
    a, b = RunLog(), RunLog()
    assert a.cg_iterations is not b.cg_iterations and a.timings is None  # one log per forward, untimed by default


def test_every_stage_holds_its_group():
    model = DepthRestorer(num_layers=3, block_matching={"search_window": 9, "k": 4, "rematch": "exact"},
                          singular={"tau": 0.4}, solver={"fixed_iters": (4, 2)}, initial={"fill": "jbf"})
    c = model.config
    assert isinstance(model.init["denoise"], DenoiseInit) and isinstance(model.init["upsample"], UpsampleInit)
    for task in ("denoise", "upsample"):
        assert model.init[task].settings == c.initial and model.init[task].sided_fill == c.sided_fill
    assert model.init["upsample"].upsampling == c.upsampling
    assert model.init["denoise"].singular is model.singular_detector  # Q⁰ and the supported pixels: the model's
    assert model.block_matcher.settings == c.block_matching and model.singular_detector.settings == c.singular
    assert isinstance(model.block_matcher, BlockMatcher)
    for i, layer in enumerate(model.layers):
        assert not hasattr(layer, "block_matcher")  # one matcher, the model's: it owns h, shared by every layer
        detector = _step(layer, SingularTest).detector
        assert isinstance(detector, SingularDetector) and detector.settings == c.singular
        assert isinstance(layer.linear_solver, LinearSolver) and layer.linear_solver.settings == c.solver
        assert [t.settings for t in layer.terms["denoise"] if isinstance(t, GuidedPriorTerm)] == [c.guided_prior]
        reader = _step(layer, MatchReader)
        assert reader.value == c.value_prior and reader.clean == c.clean_samples
        assert layer.upsampling == c.upsampling
        # the layers of block_matching.match_layers match again, the others do not
        assert any(isinstance(s, Rematch) for s in layer.steps["denoise"]) == (i in c.block_matching.match_layers)
    post = {type(step): step for task in ("denoise", "upsample") for step in model.post[task]}
    assert post[EdgeSnapStep].settings == c.edge_snap and post[EdgeRefitStep].settings == c.edge_refit
    assert post[FidelityBandStep].settings == c.fidelity
    assert post[OutputHoldStep].settings == c.upsample_hold and post[OutputHoldStep].upsampling == c.upsampling
    # the overrides reached the groups the stages hold
    assert model.block_matcher.settings.rematch == "exact"
    assert _step(model.layers[1], SingularTest).detector.settings.tau == 0.4
    assert model.layers[2].linear_solver.settings.fixed_iters == (4, 2)
    assert model.init["denoise"].settings.fill == "jbf"


def test_only_the_block_matcher_holds_state():
    keys = set(DepthRestorer(**SMALL).state_dict())
    assert keys == {"block_matcher.log_temperature", "block_matcher.log_color_weight"} | {
        f"layers.{i}.raw_{n}" for i in range(SMALL["num_layers"]) for n in ("lam", "eta", "gamma", "mu1", "mu2")}


def test_the_layer_runs_the_settings_its_stage_holds(scene):
    """A stage swapped for one with other settings changes the forward: the layer reads them from the stage."""
    model = DepthRestorer(**SMALL, solver={"fixed_iters": (5,)})
    base = model.restore_with_details(scene["depth"], scene["rgb"]).info["cg_iterations"]
    solver = model.layers[0].linear_solver
    model.layers[0].linear_solver = LinearSolver(dataclasses.replace(solver.settings, fixed_iters=(1,)), 0)
    swapped = model.restore_with_details(scene["depth"], scene["rgb"]).info["cg_iterations"]
    assert base[0] > 1 and swapped[0] == 1


@pytest.mark.parametrize("timed", [False, True])
def test_stages_record_into_the_run_log(scene, timed):
    """Each stage appends to the observation's log; the stage times appear in ``info["seconds"]`` only when asked."""
    model = DepthRestorer(**SMALL)
    calls = []
    hooked = {"block_matcher": model.block_matcher, "singular_detector": _step(model.layers[0], SingularTest).detector}
    for name, module in hooked.items():
        module.register_forward_hook(lambda mod, args, out, n=name: calls.append(n))
    rematch = model.block_matcher.rematch  # a scheduled layer's matching (the forward matches x⁰)

    def counted_rematch(*args, **kwargs):
        calls.append("block_matcher")
        return rematch(*args, **kwargs)

    model.block_matcher.rematch = counted_rematch
    info = model.restore_with_details(scene["depth"], scene["rgb"], timings=timed).info
    assert len(info["cg_iterations"]) == SMALL["num_layers"]
    assert "singular_detector" in calls
    # x⁰'s matches and those of each scheduled layer go through the model's one matcher
    scheduled = sum(i in model.config.block_matching.match_layers for i in range(SMALL["num_layers"]))
    assert calls.count("block_matcher") == 1 + scheduled
    if timed:
        assert {"block_matching", "singular", "cg", "total"} <= set(info["seconds"])
    else:
        assert info["seconds"] == {}
