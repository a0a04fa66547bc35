"""The guidance network (issue 14 item 2): per-pixel multipliers of the layers' thresholds."""
import json
import math

import pytest
import torch

from torch_depth_sr import DepthRestorer, ParameterError, RestorerConfig
from torch_depth_sr.config import Guidance
from torch_depth_sr.guidance import MAX_LOG_MULTIPLIER, GuidanceMaps, GuidanceNet

SMALL = dict(num_layers=3, block_matching={"search_window": 9, "k": 4})


def _perturb(model: DepthRestorer, seed: int = 0, scale: float = 0.5) -> DepthRestorer:
    """Give every weight of the guidance network (heads included) a random value, so its maps differ from 1."""
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in model.guidance.parameters():
            p.copy_(scale * torch.randn(p.shape, generator=g))
    return model


class TestGuidanceNet:
    def test_untrained_maps_are_exactly_one(self):
        net = GuidanceNet(num_layers=2, channels=8)
        x = torch.randn(2, 1, 20, 24)
        maps = net.prepare(torch.rand(2, 3, 20, 24)).maps(1, x, torch.ones_like(x), torch.randn_like(x))
        assert isinstance(maps, GuidanceMaps)
        assert maps.tv.shape == (2, 2, 20, 24) and maps.nonlocal_.shape == (2, 2, 20, 24)
        assert maps.outlier.shape == (2, 1, 20, 24)
        assert all(bool((m == 1).all()) for m in maps)

    def test_multipliers_are_bounded_and_the_outlier_map_lives_on_the_observation_grid(self):
        net = GuidanceNet(num_layers=1, channels=4)
        with torch.no_grad():
            for p in net.parameters():
                p.fill_(5.0)  # saturates the tanh
        x = torch.randn(1, 1, 16, 16)
        q = torch.ones(1, 1, 4, 4)  # ×4 upsampling: Q and the residual are coarser
        maps = net.prepare(torch.rand(1, 3, 16, 16)).maps(0, x, q, torch.zeros_like(q))
        assert maps.outlier.shape == (1, 1, 4, 4) and maps.tv.shape == (1, 2, 16, 16)
        lo, hi = math.exp(-MAX_LOG_MULTIPLIER), math.exp(MAX_LOG_MULTIPLIER)
        for m in maps:
            assert bool(((m >= lo * (1 - 1e-6)) & (m <= hi * (1 + 1e-6))).all())

    @pytest.mark.parametrize("max_multiplier", [1.0, 8.0, 16.0])
    def test_the_range_is_a_parameter(self, max_multiplier):
        net = GuidanceNet(num_layers=1, channels=4, max_multiplier=max_multiplier)
        assert net.max_log_multiplier == math.log(max_multiplier)
        with torch.no_grad():
            for p in net.parameters():
                p.fill_(5.0)
            net.heads[0].bias[:2] = -5.0  # the TV maps saturate low, the others high
        x = torch.randn(1, 1, 16, 16)
        maps = net.prepare(torch.rand(1, 3, 16, 16)).maps(0, x, torch.ones_like(x), torch.zeros_like(x))
        lo, hi = 1 / max_multiplier, max_multiplier
        for m in maps:
            assert bool(((m >= lo * (1 - 1e-5)) & (m <= hi * (1 + 1e-5))).all())
        assert math.isclose(float(maps.nonlocal_.detach().max()), hi, rel_tol=1e-4)
        if max_multiplier == 1.0:  # no range: every map is exactly 1, whatever the weights
            assert all(bool((m == 1).all()) for m in maps)

    def test_default_range_is_the_former_constant(self):
        assert GuidanceNet(num_layers=1).max_log_multiplier == MAX_LOG_MULTIPLIER == math.log(4.0)
        assert Guidance().range == 4.0 and RestorerConfig().replace(guidance={}).guidance.range == 4.0

    def test_no_colour_guide_runs(self):
        net = GuidanceNet(num_layers=1, channels=4)
        x = torch.randn(1, 1, 12, 12)
        assert net.prepare(None, like=x).guide_features.shape == (1, 4, 12, 12)
        with pytest.raises(ValueError, match="like"):
            net.prepare(None)

    def test_exception(self):
        with pytest.raises(ValueError, match="num_layers"):
            GuidanceNet(num_layers=0)
        with pytest.raises(ValueError, match="max_multiplier"):
            GuidanceNet(num_layers=1, max_multiplier=0.5)


class TestGuidedRestorer:
    def test_off_by_default_and_no_state_keys(self):
        m = DepthRestorer(**SMALL)
        assert m.guidance is None and not any(k.startswith("guidance") for k in m.state_dict())

    @pytest.mark.parametrize("scale_factor", [1, 4])
    def test_untrained_network_leaves_the_output_bit_identical(self, scene, scale_factor):
        depth = scene["depth"]
        if scale_factor > 1:
            depth = torch.nn.functional.avg_pool2d(scene["gt"], scale_factor) + 0.5
        plain = DepthRestorer(**SMALL)(depth, scene["rgb"])
        guided = DepthRestorer(guidance={}, **SMALL)
        assert guided.guidance is not None
        assert torch.equal(guided(depth, scene["rgb"]), plain)
        # trainable, the forward runs with autograd (the scalar model then differs from its frozen self by an ulp)
        plain_t = DepthRestorer(trainable=True, **SMALL)(depth, scene["rgb"]).detach()
        trainable = DepthRestorer(guidance={}, trainable=True, **SMALL)
        assert torch.equal(trainable(depth, scene["rgb"]).detach(), plain_t)

    def test_isotropic_untrained_is_bit_identical(self, scene):
        plain = DepthRestorer(weights={"isotropic": True}, **SMALL)(scene["depth"], scene["rgb"])
        guided = DepthRestorer(weights={"isotropic": True}, guidance={}, **SMALL)(scene["depth"], scene["rgb"])
        assert torch.equal(guided, plain)

    def test_trained_network_changes_the_output_and_every_weight_gets_a_gradient(self, scene):
        plain = DepthRestorer(**SMALL)(scene["depth"], scene["rgb"])
        m = _perturb(DepthRestorer(guidance={"channels": 4}, trainable=True, **SMALL))
        out = m(scene["depth"], scene["rgb"])
        assert torch.isfinite(out).all() and not torch.equal(out.detach(), plain)
        ((out - scene["gt"]) ** 2 * scene["mask"]).mean().backward()
        for n, p in m.guidance.named_parameters():  # with nonzero heads the gradient reaches the whole network
            assert p.grad is not None and torch.isfinite(p.grad).all() and p.grad.abs().sum() > 0, n

    def test_save_load_round_trip(self, scene, tmp_path):
        m = _perturb(DepthRestorer(guidance={"channels": 6}, **SMALL), seed=1)
        m.save(tmp_path / "guided")
        back = DepthRestorer.load(tmp_path / "guided")
        assert back.config.guidance is not None and back.config.guidance.channels == 6
        assert torch.equal(back(scene["depth"], scene["rgb"]), m(scene["depth"], scene["rgb"]))
        state = torch.load(tmp_path / "guided" / "state_dict.pt", weights_only=True)
        assert any(k.startswith("guidance.heads.2.") for k in state)

    def test_a_version1_file_without_the_guidance_fields_loads_as_the_scalar_model(self, version1_model, tmp_path):
        folder = version1_model("denoise")  # the shipped denoiser's version-1 file, older than the guidance network
        assert not {"guidance_net", "guidance_channels", "guidance_range"} & set(
            json.loads((folder / "config.json").read_text()))
        m = DepthRestorer.load(folder)
        assert m.config.guidance is None and m.guidance is None  # version 1's default: no network
        assert not any(k.startswith("guidance") for k in m.state_dict())
        m.save(tmp_path / "v2")
        written = json.loads((tmp_path / "v2" / "config.json").read_text())
        assert "guidance" in written and written["guidance"] is None  # saved: off, in so many words
        assert DepthRestorer.load(tmp_path / "v2").guidance is None

    def test_a_version1_guided_file_without_the_range_loads_with_4_and_save_writes_it(self, scene, version1_model,
                                                                                     tmp_path):
        d, c = scene["depth"], scene["rgb"]
        shipped = DepthRestorer.from_pretrained("denoise-guided")
        full = DepthRestorer.load(version1_model("denoise-guided"))  # the file it shipped with: range 16
        assert full.config == shipped.config and full.config.guidance.range == 16
        assert torch.equal(full(d, c), shipped(d, c))
        old = DepthRestorer.load(version1_model("denoise-guided", drop=("guidance_range",)))
        assert old.config.guidance.range == 4.0 and old.guidance.max_log_multiplier == math.log(4.0)  # version 1's
        assert old.config == shipped.config.replace(guidance={"range": 4.0})
        assert not torch.equal(old(d, c), shipped(d, c))  # the same weights, another range: another model
        old.save(tmp_path / "v2")
        written = json.loads((tmp_path / "v2" / "config.json").read_text())
        assert written["guidance"] == {"channels": 16, "range": 4.0}
        back = DepthRestorer.load(tmp_path / "v2")
        assert back.config == old.config and torch.equal(back(d, c), old(d, c))

    def test_range_is_saved(self, tmp_path):
        m = DepthRestorer(guidance={"channels": 4, "range": 8.0}, **SMALL)
        m.save(tmp_path / "r8")
        back = DepthRestorer.load(tmp_path / "r8")
        assert back.config.guidance.range == 8.0 and back.guidance.max_log_multiplier == math.log(8.0)

    def test_config_fields_are_checked_and_belong_to_the_guidance_group(self):
        c = RestorerConfig().replace(guidance={"channels": 8})
        assert c.guidance == Guidance(channels=8) and DepthRestorer(c).guidance is not None
        for bad in (1, True, "on"):  # the group, a dict of its fields, or None
            with pytest.raises(ParameterError, match="guidance"):
                RestorerConfig(guidance=bad)
        with pytest.raises(ParameterError, match="guidance.channels"):
            RestorerConfig().replace(guidance={"channels": 0})
        c = RestorerConfig().replace(guidance={"range": 16.0})
        assert c.guidance.range == 16.0
        for bad in (0.5, 0, -4.0, math.inf, math.nan, "8", True):
            with pytest.raises(ParameterError, match="guidance.range"):
                RestorerConfig().replace(guidance={"range": bad})


class TestShippedAndBench:
    def test_shipped_guided_model_loads_with_its_network(self):
        m = DepthRestorer.from_pretrained("denoise-guided")
        assert m.config.guidance is not None and m.guidance is not None
        assert m.guidance.max_log_multiplier == math.log(m.config.guidance.range)
        assert not any(p.requires_grad for p in m.parameters())
        heads = torch.cat([p.flatten() for p in m.guidance.heads.parameters()])
        assert heads.abs().max() > 0  # trained: the maps are not all 1

    def test_bench_trained_method_loads_a_candidate_folder(self, scene, tmp_path):
        from torch_depth_sr.errors import UsageError
        from torch_depth_sr.evaluation.bench import _parse_pretrained
        from torch_depth_sr.evaluation.methods import run_method

        m = _perturb(DepthRestorer(guidance={"channels": 4}, **SMALL), seed=2)
        m.save(tmp_path / "candidate")
        sample = {"depth": scene["depth"][0], "rgb": scene["rgb"][0]}
        out = run_method("trained", sample, pretrained=_parse_pretrained(str(tmp_path / "candidate")))
        assert torch.equal(out, m(scene["depth"], scene["rgb"]))
        assert _parse_pretrained(None) is None
        with pytest.raises(UsageError, match="not a saved model folder"):
            _parse_pretrained(str(tmp_path))
