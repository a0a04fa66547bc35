"""Issue 27: the speed tiers by name (``fast``, ``default``, ``best``) through every entry point, and the kernel
changes of the speed work against their references (each must keep the outputs bit for bit)."""
from __future__ import annotations

import pytest
import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.config import PRESETS, TIERS, TRAINED_PRESETS, preset_config
from torch_depth_sr.precision import network_precision


@pytest.fixture(scope="module")
def sample():
    from torch_depth_sr.datasets.synthetic import make_scene

    s = make_scene(40, 48, seed=3)
    g = torch.Generator().manual_seed(27)
    y = s["gt"] + 3.0 * torch.randn(s["gt"].shape, generator=g)
    y[..., 10:14, 20:26] = 0  # a hole
    return {"depth": y.clamp_min(0), "rgb": s["rgb"], "gt": s["gt"]}


# ---- the tiers ------------------------------------------------------------------------------------------------
def test_every_tier_is_a_name_of_from_preset():
    assert TIERS == ("fast", "default", "best")
    assert set(TIERS) <= set(PRESETS) | set(TRAINED_PRESETS)
    assert DepthRestorer.from_preset("full").config == DepthRestorer().config  # the frozen defaults
    for tier, shipped in (("default", "denoise-default"), ("best", "denoise-best")):
        model, saved = DepthRestorer.from_preset(tier), DepthRestorer.from_pretrained(shipped)
        assert model.config == saved.config
        assert all(torch.equal(a, b) for a, b in zip(model.state_dict().values(), saved.state_dict().values()))
    # best is denoise-refined with its refiner fine-tuned (tenth stop): the same configuration and layers, but for the
    # step-3 lattice of its re-matching (seventeenth stop)
    best, refined = DepthRestorer.from_preset("best"), DepthRestorer.from_pretrained("denoise-refined")
    assert best.config == refined.config.replace(block_matching={"rematch_lattice": 3})
    same = {k: torch.equal(v, refined.state_dict()[k]) for k, v in best.state_dict().items()}
    assert all(v for k, v in same.items() if not k.startswith("refiner."))
    assert not all(v for k, v in same.items() if k.startswith("refiner."))
    fast = DepthRestorer.from_preset("fast")
    assert fast.config == preset_config("fast") == DepthRestorer.from_pretrained(TRAINED_PRESETS["fast"]).config
    assert fast.config.block_matching.match_layers == ()  # one block-matching pass, on x⁰
    assert fast.config.num_layers < DepthRestorer().config.num_layers


def test_a_trained_tier_takes_overrides_and_trainable():
    m = DepthRestorer.from_preset("fast", edge_snap=None, trainable=True)
    assert m.config.edge_snap is None
    assert any(p.requires_grad for p in m.parameters())
    with pytest.raises(ValueError, match="allowed are"):
        preset_config("fastest")


@pytest.mark.parametrize("name", TIERS)
def test_every_tier_takes_float64(name, sample):
    """numpy's default dtype reaches the trained tiers too: a float64 frame runs (the networks in their own float32)
    and comes back float64, the same restoration as the float32 frame to well under the noise (sigma 3). Both in
    float32 networks: ``"auto"`` would run the float32 frame's in bfloat16 on a processor with AMX (the float64
    frame's stay float32), and this test is about the dtype's path, not that arithmetic (test_golden.py's)."""
    m = DepthRestorer.from_preset(name)
    y, rgb = sample["depth"][None], sample["rgb"][None]
    with torch.no_grad(), network_precision("float32"):
        single, double = m(y, rgb), m(y.double(), rgb.double())
    assert double.dtype == torch.float64 and torch.isfinite(double).all()
    assert (double - single.double()).abs().median() < 1e-3


def test_the_tiers_are_bench_methods(sample):
    from torch_depth_sr.evaluation.methods import TIER_METHODS, run_method

    assert TIER_METHODS == {"fast": "fast", "default": "default", "best": "best"}
    s = {"depth": sample["depth"], "rgb": sample["rgb"]}
    with torch.no_grad():
        want = DepthRestorer.from_preset("fast")(sample["depth"][None], sample["rgb"][None])
    got = run_method("fast", s)
    assert torch.equal(got, want)
    assert torch.equal(run_method("full-fast", s), want)  # the former name of the fast tier
    changed = run_method("fast", s, config={"edge_snap": None, "edge_refit": None})  # overrides keep the training
    assert changed.shape == want.shape and torch.isfinite(changed).all()


def test_the_speed_track_runs_the_tiers():
    from torch_depth_sr.evaluation.speed import measure

    row = measure("fast", 24, 32, 1, repeats=1)
    assert row["method"] == "fast" and row["stages"]["total"] > 0 and len(row["cg_iterations"]) == preset_config("fast").num_layers
    assert set(row["post_stages"]) == {"snap", "refine"}


def test_restore_depth_transform_takes_the_tier_by_name(sample):
    from torch_depth_sr import restore_depth
    from torch_depth_sr.errors import DepthSRError
    from torch_depth_sr.transforms import RestoreDepth

    out = RestoreDepth(preset="fast")({"depth": sample["depth"].clone(), "rgb": sample["rgb"]})["depth"]
    with torch.no_grad():
        want = restore_depth(sample["depth"], sample["rgb"], model=DepthRestorer.from_preset("fast"))
    assert torch.equal(out, want)
    assert RestoreDepth(preset="full", num_layers=2).restorer.config.num_layers == 2
    with pytest.raises(DepthSRError, match="preset"):
        RestoreDepth(preset="fast", pretrained="denoise")


# ---- the kernels: bit for bit against their references --------------------------------------------------------
def test_edge_steps_skip_the_samples_they_may_not_change():
    """snap_to_sides and refit_to_measurements compute only the active samples on the CPU; the result is that of
    the computation over every sample, masked (the reference: ``active=None`` per sample, or x itself)."""
    from torch_depth_sr.edge_snap import refit_to_measurements, snap_to_sides

    g = torch.Generator().manual_seed(0)
    x = (torch.rand(3, 1, 20, 24, generator=g) * 4).round() * 3 + torch.rand(3, 1, 20, 24, generator=g)
    rgb = torch.rand(3, 3, 20, 24, generator=g)
    y, obs = x + 0.1 * torch.randn(x.shape, generator=g), (torch.rand(x.shape, generator=g) > 0.2).float()
    for active in ([True, False, True], [False, False, False], [True, True, True]):
        a = torch.tensor(active).view(3, 1, 1, 1)
        for rounds in (1, 2):
            got = snap_to_sides(x, rgb, rounds=rounds, radius=2, active=a)
            want = torch.stack([snap_to_sides(x[i:i + 1], rgb[i:i + 1], rounds=rounds, radius=2)[0] if active[i]
                                else x[i] for i in range(3)])
            assert torch.equal(got, want)
        got = refit_to_measurements(x, y, obs, rgb, radius=3, band=1.0, edge=2.0, active=a)
        want = torch.stack([refit_to_measurements(x[i:i + 1], y[i:i + 1], obs[i:i + 1], rgb[i:i + 1], radius=3,
                                                  band=1.0, edge=2.0)[0] if active[i] else x[i] for i in range(3)])
        assert torch.equal(got, want)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64, torch.float16])
def test_percentiles_by_selection_are_torch_quantile(dtype):
    from torch_depth_sr.noise import _percentiles

    g = torch.Generator().manual_seed(1)
    for n in (2, 3, 101, 5000, 20011):
        for scale in (1e-3, 1.0, 1e4):
            v = (torch.randn(n, generator=g, dtype=torch.float64) * scale).to(dtype)
            for vals in (v, v.round(), v.abs()):
                ref_dt = torch.float64 if vals.dtype == torch.float64 else torch.float32
                want = torch.quantile(vals.to(ref_dt), torch.tensor([0.01, 0.99], dtype=ref_dt)).to(vals.dtype)
                assert torch.equal(_percentiles(vals), want)


def test_grid_step_shortcut_decides_as_the_full_count():
    from torch_depth_sr.noise import _grid_step

    def reference(vals, default):
        uniq = torch.unique(vals)
        if uniq.numel() < 2 or uniq.numel() > vals.numel() // 4:
            return default
        step = float((uniq[1:] - uniq[:-1]).min())
        ratio = uniq / step
        if float((ratio - ratio.round()).abs().max()) < 1e-4 and float(ratio.abs().max()) < 2**40:
            return step
        return default

    g = torch.Generator().manual_seed(2)
    for n in (100, 4096, 5000, 40000):
        noisy = torch.randn(n, generator=g, dtype=torch.float64) * 30 + 100
        for vals in (noisy, noisy.round(), (noisy / 2).round() * 2, noisy.round() + 0.5 * (noisy > 100),
                     torch.cat([noisy[: n // 2].round(), noisy[n // 2:]])):
            assert _grid_step(vals, 0.0) == reference(vals, 0.0)


def test_cg_without_the_unused_last_direction_is_the_textbook_loop():
    """conjugate_gradient stops after the last update of x instead of forming a direction nobody reads: x, the
    iteration counts and the residuals are those of the loop of before (copied here as the reference)."""
    from torch_depth_sr.operators import laplacian
    from torch_depth_sr.solvers.cg import conjugate_gradient
    from torch_depth_sr.solvers.dct import NeumannPreconditioner

    def reference(apply_a, b, x, precond, tol, max_iter):
        dot = lambda u, v: (u * v).flatten(1).sum(1)  # noqa: E731
        view = lambda t: t.view(-1, *([1] * (b.ndim - 1)))  # noqa: E731
        bn = torch.linalg.vector_norm(b.flatten(1), dim=1)
        bn = torch.where(bn > 0, bn, torch.ones_like(bn))
        r = b - apply_a(x)
        rel = torch.linalg.vector_norm(r.flatten(1), dim=1) / bn
        done, its = rel <= tol, torch.zeros(b.shape[0], dtype=torch.long)
        z = precond(r)
        p, rz = z, dot(r, z)
        for _ in range(max_iter):
            ap = apply_a(p)
            pap = dot(p, ap)
            active = ~done & (pap > 0)
            done = done | ~active
            alpha = torch.where(active, rz / torch.where(active, pap, torch.ones_like(pap)), torch.zeros_like(pap))
            x = x + view(alpha) * p
            r = r - view(alpha) * ap
            rel = torch.where(active, torch.linalg.vector_norm(r.flatten(1), dim=1) / bn, rel)
            its = its + active.long()
            done = done | (rel <= tol)
            z = precond(r)
            rz_new = dot(r, z)
            keep = ~done & (rz != 0)
            beta = torch.where(keep, rz_new / torch.where(keep, rz, torch.ones_like(rz)), torch.zeros_like(rz))
            p, rz = z + view(beta) * p, rz_new
        return x, its, rel

    g = torch.Generator().manual_seed(3)
    q = (torch.rand(2, 1, 24, 70, generator=g) > 0.3).float()
    b, x0 = torch.randn(2, 1, 24, 70, generator=g), torch.randn(2, 1, 24, 70, generator=g)
    apply_a = lambda v: q * v + 2.0 * laplacian(v)  # noqa: E731
    precond = NeumannPreconditioner(q.flatten(1).mean(1), torch.tensor(2.0))
    for max_iter in (1, 2, 5):
        res = conjugate_gradient(apply_a, b, x0=x0, precond=precond, tol=1e-30, max_iter=max_iter, early_exit=False)
        x, its, rel = reference(apply_a, b, x0, precond, 1e-30, max_iter)
        assert torch.equal(res.x, x) and torch.equal(res.iterations, its) and torch.equal(res.residual, rel)


def test_restore_depth_runs_the_default_tier_to_denoise_and_the_frozen_defaults_to_upsample():
    """Without a model or settings, restore_depth denoises with the trained default tier and upsamples with the frozen
    defaults (the preset "full"), which the tier was not trained for."""
    from torch_depth_sr import restore_depth
    from torch_depth_sr.datasets.synthetic import make_scene

    s = make_scene(32, 40, seed=2)
    depth = (s["gt"] + torch.randn(s["gt"].shape, generator=torch.Generator().manual_seed(0))).clamp_min(1)
    with torch.no_grad():
        out = restore_depth(depth, s["rgb"])
        assert torch.equal(out, restore_depth(depth, s["rgb"], model=DepthRestorer.from_preset("default")))
        assert not torch.equal(out, restore_depth(depth, s["rgb"], model=DepthRestorer.from_preset("full")))
        low = depth[..., ::2, ::2].contiguous()
        up = restore_depth(low, s["rgb"])
        assert up.shape[-2:] == depth.shape[-2:]
        assert torch.equal(up, restore_depth(low, s["rgb"], model=DepthRestorer()))


def test_the_transform_and_the_cli_default_to_what_restore_depth_runs(tmp_path):
    """Nothing named: RestoreDepth() and `torch-depth-sr restore` run restore_depth's default (the trained default
    tier to denoise, the frozen defaults to upsample), not the frozen full model everywhere; --preset names a tier."""
    import numpy as np

    from torch_depth_sr import restore_depth
    from torch_depth_sr.cli import main
    import cv2

    from torch_depth_sr.datasets.io import read_depth_stored, write_depth
    from torch_depth_sr.datasets.synthetic import make_scene
    from torch_depth_sr.model import default_model_for
    from torch_depth_sr.transforms import RestoreDepth

    s = make_scene(32, 40, seed=2)
    depth = (s["gt"] + torch.randn(s["gt"].shape, generator=torch.Generator().manual_seed(0))).clamp_min(1)
    with torch.no_grad():
        want = restore_depth(depth, s["rgb"])
        low = depth[..., ::2, ::2].contiguous()
        up = restore_depth(low, s["rgb"])
    assert default_model_for(depth, s["rgb"]) is default_model_for(depth.reshape(32, 40).numpy(), s["rgb"].reshape(3, 32, 40))
    assert default_model_for(low, s["rgb"]).config == DepthRestorer().config
    t = RestoreDepth()
    assert t.restorer is None and "restore_depth's default" in repr(t)
    assert torch.equal(t({"depth": depth.clone(), "rgb": s["rgb"]})["depth"], want)
    assert torch.equal(t({"depth": low.clone(), "rgb": s["rgb"]})["depth"], up)
    # the command line, one 16-bit map and its colour
    mm = (depth.reshape(32, 40).numpy() * 10).astype(np.uint16)
    rgb8 = (s["rgb"].reshape(3, 32, 40).permute(1, 2, 0).numpy() * 255).round().astype(np.uint8)
    write_depth(tmp_path / "d.png", mm)
    cv2.imwrite(str(tmp_path / "c.png"), rgb8[:, :, ::-1])
    for flags, model in (([], None), (["--preset", "fast"], DepthRestorer.from_preset("fast"))):
        out = tmp_path / f"out{len(flags)}.png"
        assert main(["restore", str(tmp_path / "d.png"), str(tmp_path / "c.png"), "-o", str(out)] + flags) == 0
        colour = torch.from_numpy(rgb8).permute(2, 0, 1)[None]
        with torch.no_grad():
            expected = restore_depth(read_depth_stored(tmp_path / "d.png"), colour, model=model)
        assert np.array_equal(read_depth_stored(out), expected)


def test_restore_depth_loads_its_default_model_once(monkeypatch):
    """The trained default tier is read from its files once per process, not on every call (about 50 ms each, paid
    per frame by a DataLoader calling restore_depth)."""
    from torch_depth_sr import model as model_module
    from torch_depth_sr import restore_depth

    model_module._shipped_default.cache_clear()
    loads = []
    real = DepthRestorer.from_preset.__func__
    counted = classmethod(lambda cls, *a, **k: loads.append(a) or real(cls, *a, **k))
    monkeypatch.setattr(DepthRestorer, "from_preset", counted)
    depth = 50 + torch.randn(1, 1, 24, 32, generator=torch.Generator().manual_seed(0))
    first = restore_depth(depth, torch.rand(1, 3, 24, 32, generator=torch.Generator().manual_seed(1)))
    again = restore_depth(depth, torch.rand(1, 3, 24, 32, generator=torch.Generator().manual_seed(1)))
    assert torch.equal(first, again) and loads == [("default",)]
    model_module._shipped_default.cache_clear()
