"""The networks' arithmetic (torch_depth_sr.precision): when "auto" picks bfloat16, the setting's checks, and that
bfloat16 reaches the convolutions only."""
from __future__ import annotations

import pytest
import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.config import RestorerConfig
from torch_depth_sr.errors import ParameterError
from torch_depth_sr.precision import native_bfloat16, network_precision, uses_bfloat16
from torch_depth_sr.refiner import EdgeRefiner


def _trained_refiner(precision: str) -> EdgeRefiner:
    torch.manual_seed(0)
    ref = EdgeRefiner(channels=8, layers=1, precision=precision)
    torch.nn.init.normal_(ref.body[-1].weight, std=0.1)  # untrained, the last layer is zero: make the step non-zero
    return ref.requires_grad_(False)


def test_auto_picks_bfloat16_for_inference_on_native_hardware_only():
    net = _trained_refiner("auto")
    x32, x64 = torch.zeros(1, 1, 4, 4), torch.zeros(1, 1, 4, 4, dtype=torch.float64)
    native = native_bfloat16(torch.device("cpu"))
    with torch.no_grad():
        assert uses_bfloat16("auto", net, x32) is native
        assert uses_bfloat16("auto", net, x64) is False  # float64 asks for precision
    assert uses_bfloat16("auto", net, x32.requires_grad_()) is False  # a gradient through the network: float32
    assert uses_bfloat16("auto", net.requires_grad_(True), torch.zeros(1, 1, 4, 4)) is False  # training it
    assert uses_bfloat16("float32", net, x64) is False and uses_bfloat16("bfloat16", net, x64) is True


def test_the_block_overrides_every_model_and_is_undone_after():
    net = _trained_refiner("bfloat16")
    x = torch.zeros(1, 1, 4, 4)
    with network_precision("float32"):
        assert uses_bfloat16(net.precision, net, x) is False
        with network_precision("bfloat16"):
            assert uses_bfloat16("float32", net, x) is True
    assert uses_bfloat16(net.precision, net, x) is True
    with pytest.raises(ValueError, match="'half'.*auto, float32, bfloat16"):
        with network_precision("half"):
            pass


def test_the_setting_is_checked_and_reaches_both_networks():
    with pytest.raises(ParameterError, match="network_precision"):
        RestorerConfig(network_precision="fp16")
    m = DepthRestorer.from_pretrained("denoise-best", network_precision="float32")
    assert m.config.network_precision == "float32"
    assert m.refiner.precision == "float32" and m.guidance.precision == "float32"
    assert DepthRestorer.from_preset("fast").refiner.precision == "auto"  # the default


def test_bfloat16_runs_the_convolutions_only():
    """The refiner in bfloat16 returns the model's dtype, within bfloat16's rounding of the float32 step, and still
    inside its clamp; the float32 features and clamp bounds are not rounded (a step of 0 leaves x exactly)."""
    torch.manual_seed(1)
    x = 1000 + 50 * torch.rand(1, 1, 24, 24)  # millimetres: bfloat16 would round 1000 to a multiple of 4
    lowres, rgb = x.clone(), torch.rand(1, 3, 24, 24)
    ref32, ref16 = _trained_refiner("float32"), _trained_refiner("bfloat16")
    with torch.no_grad():
        a, b = ref32(x, lowres, rgb), ref16(x, lowres, rgb)
        lo, hi = ref16.bounds(lowres, 1)
        assert b.dtype == torch.float32
        assert bool(((b >= lo) & (b <= hi)).all())
        step = (a - x).abs().max()
        assert 0 < float((a - b).abs().max()) <= 0.02 * float(step)
        ref16.body[-1].weight.zero_()
        ref16.body[-1].bias.zero_()
        assert torch.equal(ref16(x, lowres, rgb), torch.minimum(torch.maximum(x, lo), hi))


def test_the_environment_variable_overrides_the_setting_below_a_block(monkeypatch):
    from torch_depth_sr.precision import ENVIRONMENT_VARIABLE

    net = _trained_refiner("auto")
    x = torch.zeros(1, 1, 4, 4, dtype=torch.float64)
    monkeypatch.setenv(ENVIRONMENT_VARIABLE, "bfloat16")
    assert uses_bfloat16("float32", net, x) is True
    with network_precision("float32"):
        assert uses_bfloat16("auto", net, x) is False
    monkeypatch.setenv(ENVIRONMENT_VARIABLE, "fp16")
    with pytest.raises(ValueError, match="TORCH_DEPTH_SR_NETWORK_PRECISION='fp16'; allowed are auto, float32"):
        uses_bfloat16("auto", net, x)
