"""Issue 12, items 4 (parameter validation), 7, 8 and 10: every bad input is refused with one clear
message, odd-but-valid inputs are accepted, training never loses its graph, loading names the file."""
import json
import math
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch

from torch_depth_sr import DepthRestorer, RestorerConfig, restore_depth
from torch_depth_sr.config import PRESETS, apply_overrides
from torch_depth_sr.errors import DepthSRError, DTypeError, InvalidDepthError, ModelFileError, ParameterError
from torch_depth_sr.solvers import cg_solve
from torch_depth_sr.operators import laplacian

ROOT = Path(__file__).resolve().parents[1]
TINY = dict(num_layers=2, block_matching={"search_window": 7, "k": 4})


def _depth(h=24, w=32, seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (100 + 5 * rng.random((h, w))).astype(np.float32)


def _rgb(h=24, w=32, seed=1) -> np.ndarray:
    return (np.random.default_rng(seed).random((h, w, 3)) * 255).astype(np.uint8)


def _run_child(code: str, env_extra: dict | None = None) -> subprocess.CompletedProcess:
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(ROOT), **(env_extra or {}))
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=env,
                          timeout=300)


# ---- item 4: parameters --------------------------------------------------------------------------
BAD_FIELDS = [
    ("num_layers", 0), ("num_layers", 2.5), ("num_layers", True), ("degradation", "nearest"), ("terms", ("tv",)),
    ("terms", ("nonlocal", "nonlocal")), ("edge_snap", "on"),
    ("weights.lam", -1.0), ("weights.lam", 0.0), ("weights.lam", float("nan")), ("weights.lam", "one"),
    ("weights.eta", -2.0), ("weights.gamma", float("inf")), ("weights.mu1", 0), ("weights.mu2", -0.5),
    ("guided_prior.weight", -1.0), ("guided_prior.weight", float("nan")), ("weights.isotropic", "yes"),
    ("initial.fill", "bilateral"), ("upsampling.init", "nearest"), ("initial.kernel_size", 0),
    ("initial.sigma_space", 0.0), ("initial.sigma_color", -1.0), ("upsampling.jbu.radius", -1),
    ("upsampling.jbu", {"size": 3}), ("upsampling.multipliers", {"tau": 2.0}), ("block_matching.block_size", 4),
    ("block_matching.block_size", 0), ("block_matching.search_window", 8), ("block_matching.k", 0),
    ("block_matching.k", 2.5), ("block_matching.k", 1000), ("block_matching.color_weight", -1.0),
    ("block_matching.temperature", 0.0), ("block_matching.match_layers", 3), ("block_matching.match_layers", (1, -1)),
    ("block_matching.match_layers", ("2",)), ("singular.tau", 0.0), ("singular.tau", 1.5),
    ("singular.sigma_floor", 0.0), ("singular.rounds", 0), ("singular.gate", -0.1), ("singular.gate", 2.0),
    ("solver.tol", 0.0), ("solver.tol", -1e-3), ("solver.max_iter", 0), ("solver.precondition", 1),
    ("edge_snap.rounds", 0), ("value_prior.range", 0.0), ("fidelity.width", 0.0),
]


def _nested(path: str, value):
    """``{"a": {"b": value}}`` for ``"a.b"``: the form DepthRestorer's overrides take."""
    head, *rest = path.split(".")
    for key in reversed(rest):
        value = {key: value}
    return {head: value}


@pytest.mark.parametrize("field,value", BAD_FIELDS, ids=[f"{f}={v!r}" for f, v in BAD_FIELDS])
def test_config_field_out_of_domain_is_refused(field, value):
    with pytest.raises(ParameterError) as err:
        RestorerConfig().replace(**_nested(field, value))
    msg = str(err.value)
    assert msg.startswith(field) and "must be" in msg and "got" in msg
    assert err.value.name == field
    with pytest.raises(ParameterError):  # the same check guards the model's overrides and the JSON forms
        DepthRestorer(**_nested(field, value))
    with pytest.raises(ParameterError):
        apply_overrides(RestorerConfig(), {field: value})


def test_every_setting_has_a_domain():
    import dataclasses

    from torch_depth_sr.config.groups import Group
    from torch_depth_sr.config.restorer import _GROUPS

    unchecked = []
    for kind in _GROUPS.values():
        for f in dataclasses.fields(kind):
            if f.name not in kind._CHECKS and f.name not in kind._NESTED and f.name != "quantiles":
                unchecked.append(f"{kind._NAME}.{f.name}")
    assert not unchecked, f"add a domain to the group's _CHECKS for {unchecked}"
    assert all(issubclass(k, Group) for k in _GROUPS.values())


def test_valid_configs_still_construct():
    RestorerConfig()
    RestorerConfig().replace(**TINY)
    RestorerConfig(guided_prior=None, singular={"gate": None}, upsampling={"multipliers": {}},
                   block_matching={"color_weight": 0.0, "match_layers": []})
    for changes in PRESETS.values():
        RestorerConfig().replace(**changes)
    for f in (ROOT / "torch_depth_sr" / "pretrained").glob("*/config.json"):
        RestorerConfig.from_dict(json.loads(f.read_text()))
    c = RestorerConfig().replace(block_matching={"k": np.int64(4), "match_layers": [1]},
                                 weights={"lam": np.float32(1.5)})
    assert c.block_matching.match_layers == (1,)


@pytest.mark.parametrize("sigma", [float("nan"), float("inf"), -1.0, 0.0, "1", [1.0, 2.0, 3.0], [[1.0]] * 3,
                                   np.array([1.0, np.nan]), torch.tensor([0.5, -0.5]), True, 1j, object()])
def test_invalid_noise_sigma_is_refused(sigma):
    d = np.stack([_depth(), _depth(seed=1)])[:, None]
    with pytest.raises(ParameterError, match="noise_sigma"):
        restore_depth(d, None, noise_sigma=sigma, **TINY)


def test_noise_sigma_forms_agree():
    d = np.stack([_depth(), _depth(seed=1)])[:, None]
    ref = restore_depth(d, None, noise_sigma=2.0, **TINY)
    for form in (2, [2.0], [2.0, 2.0], np.array([2.0, 2.0], ">f8"), torch.tensor(2.0), torch.tensor([2.0, 2.0])):
        np.testing.assert_array_equal(restore_depth(d, None, noise_sigma=form, **TINY), ref)


@pytest.mark.parametrize("factor", [1.5, 2.0, 0, -2, "2", True])
def test_scale_factor_must_be_a_positive_int(factor):
    with pytest.raises(ParameterError, match="scale_factor"):
        restore_depth(_depth(12, 16), _rgb(24, 32), scale_factor=factor, **TINY)


# ---- item 7: training on flat crops --------------------------------------------------------------
@pytest.mark.parametrize("implicit", [False, True])
def test_flat_crop_trains(implicit):
    torch.manual_seed(0)
    model = DepthRestorer(trainable=True, solver={"implicit_backward": implicit}, **TINY)
    depth = torch.full((2, 1, 24, 32), 100.0)
    out = model(depth, torch.rand(2, 3, 24, 32))
    assert out.requires_grad
    loss = ((out - 101.0) ** 2).mean()
    loss.backward()
    grads = [p.grad for p in model.parameters() if p.grad is not None]
    assert grads and all(bool(torch.isfinite(g).all()) for g in grads)


def test_cg_started_at_the_solution_keeps_the_graph():
    """Unrolled CG that needs no step must still differentiate like the solution A⁻¹b."""
    g = torch.Generator().manual_seed(0)
    mu = torch.tensor(2.0, dtype=torch.float64, requires_grad=True)
    b = torch.randn(2, 1, 6, 6, dtype=torch.float64, generator=g, requires_grad=True)

    def apply_a(v):
        return v + mu * laplacian(v)

    cold = cg_solve(apply_a, b, tol=1e-12, max_iter=500, implicit=False, params=(mu,))
    gb_cold, gmu_cold = torch.autograd.grad(cold.x.square().sum(), (b, mu))
    warm = cg_solve(apply_a, b, x0=cold.x.detach(), tol=1e-6, max_iter=500, implicit=False, params=(mu,))
    assert int(warm.iterations.max()) == 0 and warm.x.requires_grad
    gb_warm, gmu_warm = torch.autograd.grad(warm.x.square().sum(), (b, mu))
    torch.testing.assert_close(gb_warm, gb_cold, rtol=1e-5, atol=1e-8)
    torch.testing.assert_close(gmu_warm, gmu_cold, rtol=1e-5, atol=1e-8)


# ---- item 8: loading -----------------------------------------------------------------------------
@pytest.fixture
def saved(tmp_path) -> Path:
    DepthRestorer(**TINY).save(tmp_path / "m")
    return tmp_path / "m"


def test_round_trip_still_loads(saved):
    m = DepthRestorer.load(saved)
    assert m.config.num_layers == 2 and m.config.block_matching.match_layers == (2, 5)


class _NotATensor:
    pass


@pytest.mark.parametrize("content", ["empty", "garbage", "pickle", "wrong_keys", "text"])
def test_corrupt_state_dict_is_named(saved, content):
    f = saved / "state_dict.pt"
    if content == "empty":
        f.write_bytes(b"")
    elif content == "garbage":
        f.write_bytes(os.urandom(300))
    elif content == "text":
        f.write_text("hello")
    elif content == "pickle":
        torch.save({"x": _NotATensor()}, f)
    else:
        torch.save({"foo": torch.zeros(1)}, f)
    with pytest.raises(ModelFileError) as err:
        DepthRestorer.load(saved)
    msg = str(err.value)
    assert str(f) in msg and "not a torch_depth_sr state dict" in msg
    assert "weights_only" not in msg


def test_truncated_state_dict_is_named(saved):
    f = saved / "state_dict.pt"
    f.write_bytes(f.read_bytes()[: f.stat().st_size // 2])
    with pytest.raises(ModelFileError, match="not a torch_depth_sr state dict"):
        DepthRestorer.load(saved)


@pytest.mark.parametrize("field,value", [("weights.lam", "one"), ("block_matching.k", 2.5),
                                         ("block_matching.match_layers", 3), ("num_layers", None),
                                         ("terms", "nonlocal"), ("bogus", 1), ("weights.bogus", 1)])
def test_mistyped_config_field_is_named(saved, field, value):
    f = saved / "config.json"
    d = json.loads(f.read_text())
    group, _, name = field.rpartition(".")
    (d[group] if group else d)[name] = value
    f.write_text(json.dumps(d))
    with pytest.raises(ModelFileError) as err:
        DepthRestorer.load(saved)
    assert str(f) in str(err.value) and (group or field) in str(err.value)


def test_invalid_json_names_file_and_position(saved):
    f = saved / "config.json"
    f.write_text('{"lam": 1.0,\n "k": }')
    with pytest.raises(ModelFileError) as err:
        DepthRestorer.load(saved)
    assert str(f) in str(err.value) and "line 2" in str(err.value) and "column" in str(err.value)


@pytest.mark.parametrize("text", ["", "[1, 2]", "null", "\x00\x01"])
def test_config_json_that_is_not_an_object(saved, text):
    (saved / "config.json").write_text(text)
    with pytest.raises(ModelFileError, match="config.json"):
        DepthRestorer.load(saved)


@pytest.mark.parametrize("missing", ["config.json", "state_dict.pt", ""])
def test_missing_files_are_named(saved, missing):
    target = saved / missing if missing else saved
    if missing:
        target.unlink()
    else:
        shutil.rmtree(saved)
    with pytest.raises(ModelFileError) as err:
        DepthRestorer.load(saved)
    assert str(target) in str(err.value) or str(saved) in str(err.value)


def test_unknown_pretrained_name_still_errors():
    with pytest.raises(ValueError, match="no pretrained parameters named"):
        DepthRestorer.from_pretrained("nope")


@pytest.mark.parametrize("dtype", [">f4", ">f8", ">u2", ">i4"])
def test_big_endian_depth_is_accepted(dtype):
    d = _depth().astype(dtype)
    out = restore_depth(d, _rgb(), **TINY)
    native = restore_depth(d.astype(np.dtype(dtype).newbyteorder("=")), _rgb(), **TINY)
    assert out.dtype == native.dtype == np.dtype(dtype).newbyteorder("=") and out.dtype.isnative  # >u2 in, uint16 out
    np.testing.assert_array_equal(out, native)


def test_big_endian_rgb_and_mask_are_accepted():
    d, rgb = _depth(), _rgb()
    mask = np.ones(d.shape, ">u2")
    mask[0, 0] = 0
    ref = restore_depth(d, rgb, mask=mask.astype(np.uint16), **TINY)
    out = restore_depth(d, (rgb / 255).astype(">f4"), mask=mask, **TINY)
    np.testing.assert_allclose(out, ref, atol=1e-3)


@pytest.mark.parametrize("as_torch", [False, True])
def test_complex_mask_is_refused(as_torch):
    mask = np.ones((24, 32), np.complex64)
    with pytest.raises(DTypeError, match="mask.*complex"):
        restore_depth(_depth(), _rgb(), mask=torch.from_numpy(mask) if as_torch else mask, **TINY)


def test_all_zero_mask_blames_the_mask():
    with pytest.raises(InvalidDepthError) as err:
        restore_depth(_depth(), _rgb(), mask=np.zeros((24, 32)), **TINY)
    assert str(err.value).startswith("mask")


def test_uint16_colour_is_accepted_as_16_bit():
    rgb8 = _rgb()
    rgb16 = rgb8.astype(np.uint16) * 257  # the same colour in 16 bits
    a = restore_depth(_depth(), rgb8, **TINY)
    b = restore_depth(_depth(), rgb16, **TINY)
    np.testing.assert_allclose(a, b, atol=1e-3)
    b_torch = restore_depth(_depth(), torch.from_numpy(rgb16.astype(np.int32)).permute(2, 0, 1).to(torch.uint16),
                            **TINY)
    np.testing.assert_allclose(a, b_torch, atol=1e-3)


def test_wide_integer_colour_gets_a_16_bit_hint():
    with pytest.raises(DTypeError, match="uint16"):
        restore_depth(_depth(), _rgb().astype(np.int32) * 257, **TINY)


def test_detail_maps_follow_the_depth_type_when_upsampling():
    res = restore_depth(_depth(12, 16), _rgb(), return_details=True, **TINY)
    assert isinstance(res.depth, np.ndarray) and res.depth.shape == (24, 32)
    for m in (res.confidence, res.trusted, res.outliers):
        assert isinstance(m, np.ndarray) and m.shape == (12, 16) and m.dtype == np.float32


def test_no_torch_warnings_for_read_only_arrays_or_colour_requiring_grad():
    # torch warns once per process, so a fresh one tells whether the library triggers the warning at all
    code = """
        import warnings, numpy as np, torch
        warnings.simplefilter("error")
        from torch_depth_sr import restore_depth
        from torch_depth_sr.transforms import AddGaussianNoise
        S = dict(num_layers=2, block_matching={"search_window": 7, "k": 4})
        d = (100 + 5 * np.random.default_rng(0).random((24, 32))).astype(np.float32)
        rgb = (np.random.default_rng(1).random((24, 32, 3)) * 255).astype(np.uint8)
        m = np.ones((24, 32), np.uint8)
        for a in (d, rgb, m):
            a.flags.writeable = False
        restore_depth(d, rgb, mask=m, **S)
        restore_depth(d.astype(np.uint16), rgb, **S)
        AddGaussianNoise(1.0)({"depth": d})
        restore_depth(torch.from_numpy(d.copy()), torch.rand(3, 24, 32, requires_grad=True), **S)
        print("clean")
    """
    child = _run_child(code)
    assert child.returncode == 0 and "clean" in child.stdout, child.stderr[-2000:]


@pytest.mark.parametrize("name", ["AddGaussianNoise", "AddHoles", "AddImpulses", "AddFlyingPixels", "Downsample"])
def test_transforms_refuse_bool_depth_clearly(name):
    from torch_depth_sr import transforms

    t = getattr(transforms, name)(2) if name == "Downsample" else getattr(transforms, name)()
    with pytest.raises(DTypeError, match="depth.*bool"):
        t({"depth": torch.ones(24, 32, dtype=torch.bool)})


def test_transforms_accept_big_endian_and_read_only_depth():
    from torch_depth_sr.transforms import AddGaussianNoise

    d = _depth().astype(">f4")
    d.flags.writeable = False
    out = AddGaussianNoise(1.0, seed=0)({"depth": d, "name": "a"})["depth"]
    ref = AddGaussianNoise(1.0, seed=0)({"depth": d.astype(np.float32), "name": "a"})["depth"]
    np.testing.assert_array_equal(out, ref)
    assert out.dtype.kind == "f" and out.dtype.itemsize == 4


def test_shape_errors_carry_the_actual_and_expected_shapes():
    """Issue 10 item 4: one set of argument checks whose ShapeError says what arrived and what is allowed."""
    import torch

    from torch_depth_sr import DepthRestorer
    from torch_depth_sr.errors import ShapeError

    with pytest.raises(ShapeError) as info:
        DepthRestorer(num_layers=1)(torch.rand(1, 2, 16, 16) + 1)
    assert info.value.actual == (1, 2, 16, 16) and info.value.expected == "(B,1,H,W)"


# ---- issue 26 item 10: the last raw errors -----------------------------------------------------------
@pytest.mark.parametrize("factor", [1, 2])
@pytest.mark.parametrize("dtype", [">f4", ">u2"])
def test_big_endian_depth_colour_and_mask_give_the_native_output_bit_for_bit(dtype, factor):
    """A PFM (``>f4``) or raw 16-bit PGM (``>u2``) depth, 16-bit big-endian colour and a big-endian mask: the output
    is exactly that of the same values in native byte order, in native byte order (``>u2`` in, ``uint16`` out)."""
    d = (_depth(12, 16) * 10).astype(dtype)
    rgb = (_rgb(12 * factor, 16 * factor).astype(np.uint16) * 257).astype(">u2")
    mask = np.ones(d.shape, ">f4")
    mask[2:4, 3:6] = 0
    out = restore_depth(d, rgb, mask=mask, return_details=True, **TINY)
    native = [a.astype(a.dtype.newbyteorder("=")) for a in (d, rgb, mask)]
    ref = restore_depth(*native, return_details=True, **TINY)
    assert out.depth.dtype == np.dtype(dtype).newbyteorder("=") and out.depth.dtype.isnative
    np.testing.assert_array_equal(out.depth, ref.depth)
    np.testing.assert_array_equal(out.confidence, ref.confidence)
    assert out.depth.shape == (12 * factor, 16 * factor)


@pytest.mark.parametrize("factor", [2, 3, 4, 16])
def test_a_small_depth_is_upsampled(factor):
    """x16 of a 3x4 depth crashed in a pooling layer (noise.white_noise_sigma's 5x5 window on the low-resolution
    depth): the white-noise estimate now falls back, as its docstring says, to the second-difference estimate when
    the depth has too few 5x5 patches, so any depth the block size allows is upsampled."""
    for h, w in ((3, 4), (2, 2), (4, 4)):
        out = restore_depth(np.linspace(90, 110, h * w, dtype=np.float32).reshape(h, w), _rgb(h * factor, w * factor),
                            **TINY)
        assert out.shape == (h * factor, w * factor) and np.isfinite(out).all()


def test_below_the_block_size_is_a_shape_error():
    from torch_depth_sr.errors import ShapeError

    with pytest.raises(ShapeError, match="depth is 1x2 \\(output 1x2\\); it must be at least 3x3"):
        restore_depth(np.ones((1, 2), np.float32), None, **TINY)
    with pytest.raises(ShapeError, match="output 2x4"):
        restore_depth(np.ones((1, 2), np.float32), _rgb(2, 4), **TINY)
