"""Issue 10 (structure, not results): the restorer gives the same numbers before and after a refactor.

Runs the model on a fixed synthetic batch (denoising; guided upsampling x2 and x4 with area and bicubic
degradation; with and without holes; ablations; the shipped pretrained models; one backward through a
trainable model) and writes every output tensor to a file; ``compare`` reports the max abs difference per
case. Run it once per code base (PYTHONPATH decides which) or both at once:

    TORCH_DEPTH_SR_DATA=... python check.py both /path/to/base/checkout /path/to/new/checkout
    python check.py run out.pt          # with the package on PYTHONPATH
    python check.py compare base.pt new.pt

The models are named by version-1 settings and named configurations (:func:`_model`), built through the API of
the code base that runs: ``DepthRestorer.ablation`` and flat keywords before the version-2 config (commit
046c797 and earlier), ``preset_config`` and ``config.apply_overrides`` after it; so both sides of that change
run the same cases.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile

import torch
import torch.nn.functional as F


# parameters that moved to the module owning them: compared under their old names
_LEGACY_NAMES = {"block_matcher.log_temperature": "log_temperature"}


def _model(preset: str = "full", trainable: bool = False, **flat):
    """The model of a version-1 named configuration (``"full"`` = the defaults, ``"paper"``, ``"tv"``, ``"tv+nl"``)
    with version-1 flat settings, in the API of the code base on PYTHONPATH."""
    from torch_depth_sr import DepthRestorer

    try:
        from torch_depth_sr.config import apply_overrides, preset_config
    except ImportError:  # version 1: flat keywords, named configurations as ablations
        if preset == "full":
            return DepthRestorer(trainable=trainable, **flat)
        return DepthRestorer.ablation(preset, **flat)
    config = preset_config("default" if preset == "full" else preset)
    return DepthRestorer(apply_overrides(config, flat), trainable=trainable)


def _inputs(factor: int, degradation: str, holes: bool, dtype=torch.float32):
    from torch_depth_sr.datasets.synthetic import make_scene

    scenes = [make_scene(64, 80, seed=s) for s in (0, 1)]
    gt = torch.stack([s["gt"] for s in scenes]).to(dtype)  # (2,1,64,80)
    rgb = torch.stack([s["rgb"] for s in scenes]).to(dtype)  # (2,3,64,80)
    if factor > 1:
        h, w = gt.shape[-2] // factor, gt.shape[-1] // factor
        lr = (F.avg_pool2d(gt, factor) if degradation == "area" else
              F.interpolate(gt, size=(h, w), mode="bicubic", antialias=True, align_corners=False))
    else:
        lr = gt
    g = torch.Generator().manual_seed(1234 + factor)
    noisy = lr + 3.0 * torch.randn(lr.shape, generator=g, dtype=torch.float64).to(dtype)
    if holes:
        h, w = noisy.shape[-2:]
        noisy[0, :, h // 4: h // 4 + max(2, h // 8), w // 3: w // 3 + max(2, w // 6)] = 0
        noisy[1, :, h // 2: h // 2 + max(2, h // 10), 2: 2 + max(2, w // 8)] = 0
    return noisy.clamp_min(0), rgb


def _details(model, depth, rgb, **kw):
    if hasattr(model, "restore_with_details"):  # the tensor API (issue 10 item 1): forward returns the depth only
        r = model.restore_with_details(depth, rgb, **kw)
        plain = model(depth, rgb, **kw)  # forward gives the same depth as the details
        assert torch.equal(torch.nan_to_num(plain, nan=-1.0), torch.nan_to_num(r.depth, nan=-1.0))
    else:
        r = model(depth, rgb, return_details=True, **kw)
    out = {"depth": r.depth, "confidence": r.confidence, "trusted": r.trusted, "outliers": r.outliers,
           "cg_iterations": torch.tensor(r.info["cg_iterations"]),
           "noise_sigma": torch.tensor(r.info["noise_sigma"], dtype=torch.float64)}
    if isinstance(r.depth, torch.Tensor) and r.depth.isnan().any():
        out["depth_nan"] = r.depth.isnan()
        out["depth"] = torch.nan_to_num(r.depth, nan=-1.0)
    return out


def _layout_details(depth, rgb, **kw):
    """restore_depth on numpy / (H,W) / (1,H,W) / integer input: the layout handling outside the module."""
    import numpy as np
    from torch_depth_sr import restore_depth

    r = restore_depth(depth, rgb, return_details=True, **kw)
    as_t = lambda a: torch.from_numpy(np.asarray(a).astype(np.float64)) if not isinstance(a, torch.Tensor) else a  # noqa: E731
    out = {"depth": as_t(r.depth), "confidence": as_t(r.confidence), "trusted": as_t(r.trusted),
           "outliers": as_t(r.outliers), "cg_iterations": torch.tensor(r.info["cg_iterations"]),
           "noise_sigma": torch.tensor(r.info["noise_sigma"], dtype=torch.float64)}
    if out["depth"].isnan().any():
        out["depth_nan"] = out["depth"].isnan()
        out["depth"] = torch.nan_to_num(out["depth"], nan=-1.0)
    return out


def run(path: str) -> None:
    import torch_depth_sr
    from torch_depth_sr import DepthRestorer

    torch.manual_seed(0)
    print("package:", torch_depth_sr.__file__, file=sys.stderr)
    results = {}
    for holes in (False, True):
        tag = "holes" if holes else "full"
        y, rgb = _inputs(1, "area", holes)
        results[f"denoise/{tag}"] = _details(DepthRestorer(), y, rgb)
        results[f"denoise/{tag}/paper"] = _details(_model("paper"), y, rgb)
        results[f"denoise/{tag}/tv"] = _details(_model("tv"), y, rgb)
        results[f"denoise/{tag}/tv+nl"] = _details(_model("tv+nl"), y, rgb)
        results[f"denoise/{tag}/init_singular"] = _details(_model(init_singular=True), y, rgb)
        results[f"denoise/{tag}/no_guided_prior_on_singular"] = _details(
            _model(prior_on_singular=False, init_keep_observed=False), y, rgb)
        results[f"denoise/{tag}/jbf_exact_converged"] = _details(
            _model(init_fill="jbf", rematch="exact", cg_fixed_iters=()), y, rgb)
        results[f"denoise/{tag}/no_guide"] = _details(DepthRestorer(), y, None)
        results[f"denoise/{tag}/fill_trusted"] = _details(DepthRestorer(), y, rgb, fill="trusted")
        results[f"denoise/{tag}/pretrained"] = _details(DepthRestorer.from_pretrained("denoise"), y, rgb)
        y64, rgb64 = _inputs(1, "area", holes, torch.float64)
        results[f"denoise/{tag}/float64"] = _details(DepthRestorer(num_layers=3), y64, rgb64)
        for factor in (2, 4):
            for deg in ("area", "bicubic"):
                y, rgb = _inputs(factor, deg, holes)
                key = f"x{factor}/{deg}/{tag}"
                results[key] = _details(DepthRestorer(degradation=deg), y, rgb)
                results[key + "/fill_trusted"] = _details(DepthRestorer(degradation=deg), y, rgb, fill="trusted")
                results[key + "/bicubic_init"] = _details(
                    _model(degradation=deg, upsample_init="bicubic", upsample_tv_per_factor=False,
                           upsample_scale={"lam": 2.0}, upsample_jbu={"radius": 3}), y, rgb)
                results[key + "/paper"] = _details(_model("paper", degradation=deg), y, rgb)
                if factor == 4:
                    results[key + "/pretrained"] = _details(DepthRestorer.from_pretrained("upsample-x4"), y, rgb)
    # the layouts, dtypes and array types that restore_depth converts (numpy, (H,W), (1,H,W), uint16, uint8 colour)
    for holes in (False, True):
        tag = "holes" if holes else "full"
        y, rgb = _inputs(1, "area", holes)
        d_np, rgb_np = y[0, 0].numpy(), (rgb[0].permute(1, 2, 0) * 255).round().to(torch.uint8).numpy()
        u16 = (y[0, 0] * 10).round().numpy().astype("uint16")
        small = {"num_layers": 3}
        results[f"layout/{tag}/numpy_hw"] = _layout_details(d_np, rgb_np, **small)
        results[f"layout/{tag}/numpy_hw_trusted"] = _layout_details(d_np, rgb_np, fill="trusted", **small)
        results[f"layout/{tag}/uint16"] = _layout_details(u16, rgb_np, **small)
        results[f"layout/{tag}/uint16_trusted"] = _layout_details(u16, rgb_np, fill="trusted", **small)
        results[f"layout/{tag}/torch_chw"] = _layout_details(y[0], rgb[0], **small)
        yl, rgbl = _inputs(2, "area", holes)
        results[f"layout/{tag}/x2_numpy_hw"] = _layout_details(yl[1, 0].numpy(), rgbl[1].numpy(), **small)
    # one backward through a trainable model: gradients of every parameter that gets one
    for name, factor, deg in (("denoise", 1, "area"), ("x2-area", 2, "area"), ("x2-bicubic", 2, "bicubic")):
        y, rgb = _inputs(factor, deg, True)
        model = DepthRestorer(num_layers=3, trainable=True, degradation=deg)
        out = model(y, rgb)
        out.square().mean().backward()
        results[f"grad/{name}"] = {"out": out.detach(), **{
            _LEGACY_NAMES.get(n, n): p.grad.clone() for n, p in model.named_parameters() if p.grad is not None}}
    torch.save(results, path)
    print(f"{len(results)} cases -> {path}", file=sys.stderr)


def compare(a_path: str, b_path: str) -> int:
    a, b = torch.load(a_path), torch.load(b_path)
    worst, bad = 0.0, 0
    for case in sorted(set(a) | set(b)):
        if case not in a or case not in b:
            print(f"{case:60s} only in {'base' if case in a else 'new'}")
            bad += 1
            continue
        diffs = []
        for key in sorted(set(a[case]) | set(b[case])):
            ta, tb = a[case].get(key), b[case].get(key)
            if ta is None or tb is None or ta.shape != tb.shape:
                diffs.append(f"{key}: missing or shape differs")
                bad += 1
                continue
            d = (ta.double() - tb.double()).abs().max().item() if ta.numel() else 0.0
            worst = max(worst, d)
            if d != 0:
                diffs.append(f"{key}: {d:.3g}")
                bad += 1
        print(f"{case:60s} {'identical' if not diffs else '; '.join(diffs)}")
    print(f"\n{len(set(a) | set(b))} cases, max abs diff over every tensor: {worst:g}; {bad} tensors differ")
    return 1 if bad else 0


def both(base_root: str, new_root: str) -> int:
    paths = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, root in (("base", base_root), ("new", new_root)):
            out = os.path.join(tmp, f"{label}.pt")
            env = {**os.environ, "PYTHONPATH": os.path.abspath(root)}
            subprocess.run([sys.executable, os.path.abspath(__file__), "run", out], env=env, check=True,
                           cwd=tmp)
            paths.append(out)
        return compare(*paths)


if __name__ == "__main__":
    cmd, *args = sys.argv[1:]
    if cmd == "run":
        run(*args)
    elif cmd == "compare":
        sys.exit(compare(*args))
    elif cmd == "both":
        sys.exit(both(*args))
    else:
        sys.exit(__doc__)
