import numpy as np
import pytest
import torch

from torch_depth_sr import DepthRestorer, RestorerConfig, restore_depth
from torch_depth_sr.errors import DepthSRError, DTypeError, ShapeError


def rmse(pred, gt, mask):
    return float((((pred - gt) ** 2) * mask).sum() / mask.sum()) ** 0.5

SMALL = dict(num_layers=3, block_matching={"search_window": 9, "k": 4})


class TestDepthRestorer:
    def test_smoke_shapes_and_finite(self, scene):
        out = DepthRestorer(**SMALL)(scene["depth"], scene["rgb"])
        assert out.shape == scene["depth"].shape and out.dtype == torch.float32
        assert torch.isfinite(out).all()

    def test_improves_on_noisy_input(self, scene):
        out = DepthRestorer()(scene["depth"], scene["rgb"])
        filled_in = torch.where(scene["depth"] > 0, scene["depth"], out)
        assert rmse(out, scene["gt"], scene["mask"]) < 0.8 * rmse(filled_in, scene["gt"], scene["mask"])

    def test_default_has_eight_layers_and_frozen_has_no_grad(self):
        m = DepthRestorer()
        assert len(m.layers) == 8
        assert not any(p.requires_grad for p in m.parameters())

    @pytest.mark.parametrize("guidance_net", [False, True])
    def test_trainable_parameters_get_gradients(self, scene, guidance_net):
        m = DepthRestorer(trainable=True, guidance={} if guidance_net else None, **SMALL)
        out = m(scene["depth"], scene["rgb"])
        loss = ((out - scene["gt"]) ** 2 * scene["mask"]).mean()
        loss.backward()
        expected = {f"layers.{i}.raw_{n}" for i in range(SMALL["num_layers"])
                    for n in ("lam", "eta", "gamma", "mu1", "mu2")} | {"block_matcher.log_temperature"}
        if guidance_net:  # the guidance network's convolutions and one head per layer
            expected |= {f"guidance.{c}.{w}" for c in ("guide.0", "guide.2", "state", "mix")
                         for w in ("weight", "bias")}
            expected |= {f"guidance.heads.{i}.{w}" for i in range(SMALL["num_layers"]) for w in ("weight", "bias")}
        assert {n for n, p in m.named_parameters() if p.requires_grad} == expected  # ρ is a buffer: it picks matches
        got = {n for n, p in m.named_parameters() if p.grad is not None and bool(torch.isfinite(p.grad).all())}
        assert got == expected

    def test_functional_handles_layouts_and_runs_the_given_model(self, scene):
        m = DepthRestorer(**SMALL)
        a = m(scene["depth"], scene["rgb"])  # (B,1,H,W) float tensors: the module
        hw = restore_depth(scene["depth"][0, 0].numpy(), scene["rgb"][0].numpy(), model=m)  # (H,W) numpy
        assert isinstance(hw, np.ndarray) and hw.shape == tuple(scene["depth"].shape[-2:])
        torch.testing.assert_close(torch.from_numpy(hw)[None, None], a, rtol=0, atol=0)
        other = DepthRestorer(**SMALL, weights={"lam": 5 * DepthRestorer().config.weights.lam})
        assert not torch.equal(restore_depth(scene["depth"], scene["rgb"], model=other), a)  # model= is used
        with pytest.raises(DepthSRError, match="either a model or the settings"):
            restore_depth(scene["depth"], scene["rgb"], model=m, num_layers=2)

    def test_forward_is_the_depth_of_the_details(self, scene):
        m = DepthRestorer(**SMALL)
        r = m.restore_with_details(scene["depth"], scene["rgb"])
        assert torch.equal(m(scene["depth"], scene["rgb"]), r.depth)
        assert r.info["seconds"] == {}  # timing is opt-in
        assert set(m.restore_with_details(scene["depth"], scene["rgb"], timings=True).info["seconds"]) >= {"total"}

    def test_forward_takes_batched_float_tensors_only_and_says_where_the_rest_goes(self, scene):
        m = DepthRestorer(**SMALL)
        d = scene["depth"]
        with pytest.raises(TypeError):  # the details have their own method: no return_details/timings flags
            m(d, scene["rgb"], return_details=True)
        for bad in (d[0, 0].numpy(), d[0]):  # numpy and (1,H,W) layouts are restore_depth's business
            with pytest.raises((DTypeError, ShapeError), match="restore_depth"):
                m(bad, scene["rgb"])
        assert isinstance(restore_depth(d[0, 0].numpy(), scene["rgb"], model=m), np.ndarray)
        with pytest.raises(ShapeError, match="restore_depth"):
            m.restore_with_details(d[0], scene["rgb"])
        with pytest.raises(DTypeError, match="restore_depth"):
            m.restore_with_details(d.round().to(torch.int32), scene["rgb"])

    def test_batched_equals_per_sample(self, scene):
        d2 = torch.cat([scene["depth"], scene["depth"].flip(-1)])
        c2 = torch.cat([scene["rgb"], scene["rgb"].flip(-1)])
        m = DepthRestorer(**SMALL)
        batched = m(d2, c2)
        single = torch.cat([m(d2[i : i + 1], c2[i : i + 1]) for i in range(2)])
        torch.testing.assert_close(batched, single, atol=1e-3, rtol=1e-4)

    def test_inputs_not_modified(self, scene):
        d, c = scene["depth"].clone(), scene["rgb"].clone()
        d[0, 0, 0, 0] = float("nan")
        d_copy = d.clone()
        DepthRestorer(**SMALL)(d, c)
        assert torch.equal(torch.isnan(d), torch.isnan(d_copy))
        torch.testing.assert_close(torch.nan_to_num(d), torch.nan_to_num(d_copy))
        torch.testing.assert_close(c, scene["rgb"])

    def test_scale_equivariance(self, scene):
        """One parameter set for any unit: restoring depth×1000 gives the result×1000."""
        d = scene["depth"].double()
        c = scene["rgb"].double()
        m = DepthRestorer(**SMALL)
        torch.testing.assert_close(m(d * 1000, c), m(d, c) * 1000, rtol=1e-6, atol=1e-6)

    def test_ablations_switch_terms_off_in_the_same_code_path(self, scene):
        """The ablations are the one model with terms off, and each term they switch changes the result."""
        d, c = scene["depth"], scene["rgb"]
        tv = DepthRestorer.from_preset("tv", **SMALL)(d, c)
        tvnl = DepthRestorer.from_preset("tv+nl", **SMALL)(d, c)
        full = DepthRestorer.from_preset("full", **SMALL)(d, c)
        assert not torch.equal(tv, tvnl) and not torch.equal(tvnl, full)

    def test_details(self, scene):
        res = restore_depth(scene["depth"], scene["rgb"], return_details=True, **SMALL)
        assert res.confidence.shape == scene["depth"].shape
        assert (res.confidence[scene["depth"] == 0] == 0).all()
        assert ((res.trusted == 0) | (res.trusted == 1)).all()
        assert len(res.info["cg_iterations"]) == SMALL["num_layers"]

    def test_save_load_roundtrip(self, tmp_path, scene):
        m = DepthRestorer(**SMALL)
        m.save(tmp_path)
        m2 = DepthRestorer.load(tmp_path)
        torch.testing.assert_close(m(scene["depth"], scene["rgb"]), m2(scene["depth"], scene["rgb"]))

    def test_state_dict_saved_before_the_block_matcher_owned_h_and_rho_loads(self, tmp_path, scene):
        """Saved models keep ``log_temperature``/``log_color_weight`` at the top; both load paths move them."""
        m = DepthRestorer(DepthRestorer(**SMALL).config.replace(block_matching={"temperature": 0.7,
                                                                                "color_weight": 250.0}))
        legacy = {("log_temperature" if k == "block_matcher.log_temperature" else
                   "log_color_weight" if k == "block_matcher.log_color_weight" else k): v
                  for k, v in m.state_dict().items()}
        assert "log_temperature" in legacy and "block_matcher.log_temperature" not in legacy
        fresh = DepthRestorer(**SMALL)
        fresh.load_state_dict(legacy)  # strict: no missing, no unexpected key
        assert float(fresh.block_matcher.temperature) == pytest.approx(0.7)
        assert float(fresh.block_matcher.color_weight) == pytest.approx(250.0)
        m.save(tmp_path)
        torch.save(legacy, tmp_path / "state_dict.pt")
        m2 = DepthRestorer.load(tmp_path)
        torch.testing.assert_close(m(scene["depth"], scene["rgb"]), m2(scene["depth"], scene["rgb"]), rtol=0, atol=0)

    def test_upsampling(self, scene):
        gt = scene["gt"][..., :48, :64]
        lr = torch.nn.functional.avg_pool2d(gt, 4)
        out = restore_depth(lr, scene["rgb"], **SMALL)
        assert out.shape == gt.shape and torch.isfinite(out).all()

    def test_upsample_scale_applies_only_when_upsampling(self, scene):
        gt = scene["gt"][..., :48, :64]
        lr = torch.nn.functional.avg_pool2d(gt, 2)
        unit = {"mu1": 1.0, "mu2": 1.0}  # every multiplier 1 (version 1: upsample_scale={})
        plain = restore_depth(lr, scene["rgb"][..., :48, :64], **SMALL, upsampling={"multipliers": unit})
        scaled = restore_depth(lr, scene["rgb"][..., :48, :64], **SMALL,
                               upsampling={"multipliers": {"mu1": 3.0, "mu2": 3.0}})
        assert not torch.allclose(plain, scaled)
        same = [restore_depth(scene["depth"], scene["rgb"], **SMALL, upsampling={"multipliers": u})
                for u in (unit, {"mu1": 5.0, "mu2": 1.0})]
        torch.testing.assert_close(same[0], same[1])

    @pytest.mark.parametrize("bad", [{"tau": 2.0}, {"mu1": 0.0}, {"lam": -1.0}])
    def test_upsample_scale_rejects_unknown_or_nonpositive(self, bad):
        with pytest.raises(ValueError, match="multipliers"):
            RestorerConfig(upsampling={"multipliers": bad})
        with pytest.raises(ValueError, match="multipliers"):
            DepthRestorer(upsampling={"multipliers": bad})

    def test_fast_preset_is_close_to_the_default_and_overridable(self, scene):
        fast = DepthRestorer.from_preset("fast")  # the fast speed tier: a trained 3-layer model (issue 27)
        assert fast.config.block_matching.search_window == 7 and fast.config.block_matching.match_layers == ()
        six = DepthRestorer.from_preset("fast", block_matching={"k": 6}).config.block_matching
        assert six.k == 6 and six.search_window == 7  # the override merges into the preset's group
        a = rmse(DepthRestorer()(scene["depth"], scene["rgb"]), scene["gt"], scene["mask"])
        b = rmse(fast(scene["depth"], scene["rgb"]), scene["gt"], scene["mask"])
        assert b < 1.1 * a
        with pytest.raises(ValueError, match="allowed are"):
            DepthRestorer.from_preset("fastest")

    def test_depth_only(self, scene):
        out = restore_depth(scene["depth"], None, **SMALL)
        assert torch.isfinite(out).all()


class TestLayouts:
    def test_numpy_uint16_millimetres(self, scene):
        d = (scene["depth"][0, 0].numpy() * 10).astype(np.uint16)
        rgb = (scene["rgb"][0].permute(1, 2, 0).numpy() * 255).astype(np.uint8)
        out = restore_depth(d, rgb, **SMALL)
        assert isinstance(out, np.ndarray) and out.dtype == np.uint16 and out.shape == d.shape
        assert out.min() > 0

    def test_nan_means_missing(self, scene):
        d = scene["depth"].clone()
        nan = torch.where(d == 0, torch.full_like(d, float("nan")), d)
        torch.testing.assert_close(restore_depth(d, scene["rgb"], **SMALL), restore_depth(nan, scene["rgb"], **SMALL))

    def test_explicit_mask(self, scene):
        d = scene["depth"]
        m = torch.ones_like(d)
        m[..., :5, :5] = 0
        d2 = d.clone()
        d2[..., :5, :5] = 999.0  # hidden by the mask
        torch.testing.assert_close(restore_depth(d, scene["rgb"], mask=m, **SMALL),
                                   restore_depth(d2, scene["rgb"], mask=m, **SMALL))

    @pytest.mark.parametrize("layout", ["hw", "1hw"])
    def test_layout_kept(self, scene, layout):
        d = scene["depth"][0, 0] if layout == "hw" else scene["depth"][0]
        assert restore_depth(d, scene["rgb"][0], **SMALL).shape == d.shape


class TestErrors:
    @pytest.mark.parametrize(
        "make, match",
        [
            (lambda s: (s["depth"][:, :, None], s["rgb"]), "depth must be"),
            (lambda s: (torch.zeros(2, 3, 8, 8), s["rgb"]), "one channel"),
            (lambda s: (s["depth"], s["rgb"][..., :40, :]), "rgb"),
            (lambda s: (torch.zeros_like(s["depth"]), s["rgb"]), "no measured pixel"),
            (lambda s: (s["depth"], s["rgb"] * float("nan")), "NaN or inf"),
            (lambda s: (s["depth"], s["rgb"] * 255), r"\[0,1\]"),
            (lambda s: (s["depth"][..., :2, :2], s["rgb"][..., :2, :2]), "block size"),
            (lambda s: (-s["depth"] - 1, s["rgb"]), "negative"),
            (lambda s: (s["depth"] + float("inf"), s["rgb"]), "inf"),
            (lambda s: (s["depth"].to(torch.complex64), s["rgb"]), "dtype"),
            (lambda s: ([[1.0]], s["rgb"]), "torch.Tensor or numpy"),
        ],
    )
    def test_bad_input(self, scene, make, match):
        d, c = make(scene)
        with pytest.raises(ValueError, match=match):
            restore_depth(d, c, **SMALL)


def _optional_groups() -> list:
    """The settings groups of RestorerConfig that may be off (typed ``Optional``): the library's extensions."""
    import dataclasses
    import types
    import typing

    hints = typing.get_type_hints(RestorerConfig)
    return [f.name for f in dataclasses.fields(RestorerConfig)
            if typing.get_origin(hints[f.name]) in (typing.Union, types.UnionType)
            and type(None) in typing.get_args(hints[f.name])]


# what the paper preset documents as kept of the library (config/presets.py): guided upsampling, which the paper does
# not model, keeps the library's x⁰ and its output hold
PAPER_KEEPS = ("upsample_hold",)


def test_paper_preset_switches_every_extension_off():
    from torch_depth_sr.config import (TERMS, BlockMatchingConfig, InitConfig, LayerWeights, OutputHold,
                                       SingularConfig, SolverConfig, UpsamplingConfig)

    c = DepthRestorer.from_preset("paper").config
    optional = _optional_groups()
    assert set(PAPER_KEEPS) <= set(optional) and "edge_snap" in optional  # the discovery sees the groups
    assert {name: getattr(c, name) for name in optional if name not in PAPER_KEEPS} == \
        dict.fromkeys(set(optional) - set(PAPER_KEEPS))  # every other extension off, one added later too
    assert c.upsample_hold == OutputHold() and c.upsampling == UpsamplingConfig()  # guided upsampling: the library's
    assert c.terms == TERMS == ("nonlocal", "outliers", "singular")  # all of the paper's terms
    assert c.singular.gate is None and c.singular.support == 0 and not c.singular.line_support
    assert c.singular == SingularConfig(support=0, line_support=False, gate=None)  # the paper's test otherwise
    assert c.block_matching == BlockMatchingConfig(block_size=5, search_window=21, k=10, rematch="exact")
    assert c.initial == InitConfig(fill="pushpull")
    assert c.weights == LayerWeights()  # weights in noise-σ units
    assert c.solver == SolverConfig() and c.solver.fixed_iters  # CG keeps its fixed schedule
    with pytest.raises(ValueError, match="paper"):
        DepthRestorer.from_preset("papers")


def test_paper_preset_is_the_paper_model_built_field_by_field(scene):
    """The paper's model from its description (model.md), every optional group off but the output hold of guided
    upsampling: a group added later with a default-on value, and not switched off by the preset, makes the two
    differ."""
    from torch_depth_sr.config import (BlockMatchingConfig, InitConfig, LayerWeights, OutputHold, SingularConfig,
                                       SolverConfig, UpsamplingConfig)

    fields = dict(
        num_layers=8, degradation="area", terms=("nonlocal", "outliers", "singular"),
        weights=LayerWeights(lam=1.0, eta=2.0, gamma=3.0, mu1=2.0, mu2=0.5, isotropic=False),
        block_matching=BlockMatchingConfig(block_size=5, search_window=21, k=10, rematch="exact"),
        singular=SingularConfig(support=0, line_support=False, gate=None),  # no support rules, no gate
        solver=SolverConfig(),  # the fixed CG schedule
        initial=InitConfig(fill="pushpull", singular=False),  # x⁰ = y, holes pulled-pushed
        upsampling=UpsamplingConfig(),  # guided upsampling (not in the paper): the library's x⁰ ...
        upsample_hold=OutputHold(),  # ... and its output hold
        sided_fill=None, value_prior=None, clean_samples=None, guided_prior=None, fidelity=None, edge_snap=None,
        edge_refit=None, guidance=None, refiner=None)
    later = {name: None for name in _optional_groups() if name not in PAPER_KEEPS and name not in fields}
    paper = RestorerConfig(**fields, **later)  # and any optional group added later: off
    preset = DepthRestorer.from_preset("paper")
    assert preset.config == paper
    d, c = scene["depth"], scene["rgb"]
    assert torch.equal(preset(d, c), DepthRestorer(paper)(d, c))
    # the preset keeps nothing of the default model's extensions: its output is not the default's
    assert not torch.equal(preset(d, c), DepthRestorer()(d, c))


def test_repr_lists_the_stages_in_order():
    text = repr(DepthRestorer(num_layers=2))
    order = ["(init): ModuleDict", "(denoise): DenoiseInit", "(upsample): UpsampleInit", "(layers): ModuleList",
             "(0): UnrolledLayer", "(1): UnrolledLayer", "(post): ModuleDict", "(denoise): ModuleList",
             "EdgeSnapStep", "EdgeRefitStep", "FidelityBandStep", "(upsample): ModuleList", "OutputHoldStep"]
    at, start = [], 0
    for item in order:
        assert item in text[start:], f"{item!r} missing or out of order in\n{text}"
        start = text.index(item, start) + len(item)
        at.append(start)
    assert at == sorted(at)


def test_tv_preset_layers_hold_the_tv_term_of_the_papers_terms_only():
    from torch_depth_sr.terms import GuidedPriorTerm, TVTerm

    layer = DepthRestorer.from_preset("tv").layers[0]
    assert [type(t) for t in layer.terms["upsample"]] == [TVTerm]
    # denoising keeps the library's guided prior on untrusted pixels (the "tv" preset, like the version-1 ablation it
    # replaces, switches the paper's terms off, not that extension): no nonlocal, outlier or value-prior term
    assert [type(t) for t in layer.terms["denoise"]] == [TVTerm, GuidedPriorTerm]
    assert [type(t) for t in DepthRestorer.from_preset("tv", guided_prior=None).layers[0].terms["denoise"]] == [TVTerm]
    assert not layer.steps["denoise"] and not layer.steps["upsample"]  # no matches read, no singular test


def test_paper_model_runs_as_a_bench_method():
    from torch_depth_sr.datasets.synthetic import make_scene
    from torch_depth_sr.evaluation.methods import run_method

    s = make_scene(32, 32, seed=1)
    sample = {"depth": s["gt"] + torch.randn(s["gt"].shape, generator=torch.Generator().manual_seed(0)),
              "rgb": s["rgb"]}
    out = run_method("paper-model", sample, config={"num_layers": 2, "block_matching": {"search_window": 7}})
    assert out.shape == (1, 1, 32, 32) and bool(torch.isfinite(out).all())
    assert float((out - s["gt"]).pow(2).mean()) < float((sample["depth"] - s["gt"]).pow(2).mean())


@pytest.mark.parametrize("setting", [{"eta": 1.0}, {"value_range": None}, {"value_weight": None}])
def test_clean_sample_settings_act_only_on_samples_the_singular_gate_finds_clean(setting):
    from torch_depth_sr import DepthRestorer
    from torch_depth_sr.datasets.synthetic import make_scene

    s = make_scene(48, 48, seed=2)
    g = torch.Generator().manual_seed(0)
    clean = s["gt"] + 2 * torch.randn(s["gt"].shape, generator=g)
    spiky = clean.clone()
    spots = torch.rand(spiky.shape, generator=g) < 0.03  # 3 % impulses: far above the gate's 0.2 %
    spiky[spots] = 255.0
    y = torch.stack([clean, spiky])
    rgb = s["rgb"][None].expand(2, -1, -1, -1)
    kw = dict(num_layers=3, block_matching={"search_window": 9})
    a = DepthRestorer(clean_samples=setting, **kw)(y, rgb)  # the setting off
    b = DepthRestorer(**kw)(y, rgb)  # the defaults: clean_samples eta 0.25, value_range 1, value_weight 30
    assert torch.equal(a[1], b[1])  # outliers found: η and r as configured for every sample
    assert float((a[0] - b[0]).abs().max()) > 1e-3  # no outliers: the clean-sample values from the second layer on


def test_k_is_limited_to_the_candidates_every_pixel_has():
    """The default k (40) exceeds what a 6×6 image or the fast tier's 7×7 window offers at a corner (35):
    the stage matches all of them instead of refusing the image."""
    from torch_depth_sr import DepthRestorer
    from torch_depth_sr.block_matching._common import candidates_everywhere

    assert candidates_everywhere(6, 6, 15, include_self=False) == 35 < DepthRestorer().config.block_matching.k
    g = torch.Generator().manual_seed(0)
    y = 50 + torch.randn(1, 1, 6, 6, generator=g)
    out = DepthRestorer(num_layers=2)(y, torch.rand(1, 3, 6, 6, generator=g))
    assert out.shape == y.shape and bool(torch.isfinite(out).all())
    from torch_depth_sr.config import preset_config

    assert DepthRestorer(preset_config("fast", num_layers=1, refiner=None))(y, None).shape == y.shape  # 7×7 window


def test_guided_upsampling_matches_with_its_own_window_and_k():
    from torch_depth_sr import RestorerConfig
    from torch_depth_sr.config import preset_config

    bm = RestorerConfig().block_matching
    assert bm.window_and_k() == {"denoise": (15, 40), "upsample": (21, 10)}
    assert preset_config("fast").block_matching.window_and_k() == {"denoise": (7, 10), "upsample": (21, 10)}
    with pytest.raises(ValueError, match="upsample_k"):
        RestorerConfig().replace(block_matching={"upsample_search_window": 3})
