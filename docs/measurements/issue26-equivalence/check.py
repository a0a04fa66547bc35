"""Issue 26 (structure only): the restorer keeps its numbers, gradients and structure through the refactor.

Extends ``../issue10-equivalence/check.py``. Runs fixed synthetic batches (two 64x80 scenes, sigma = 3 noise) through

* the defaults (``DepthRestorer()``) and every named configuration, ``default``, ``fast``, ``paper``, ``tv``,
  ``tv+nl`` (``DepthRestorer.from_preset(name)`` where it exists, else the base API ``ablation`` / ``preset``);
* all seven shipped models (``DepthRestorer.from_pretrained(name)``);
* each of them on every task input: denoising (no holes, holes, holes + impulses + flying pixels) and guided
  upsampling x2 and x4 with area and bicubic degradation (no holes, holes), whatever the model was made for;
* ``fill="trusted"`` and float64 for each of them; the issue-10 cases with explicit field overrides
  (``init_singular``, ``prior_on_singular=False``, JBF x0 with exact re-matching and CG to tolerance, no guide,
  bicubic x0 ...); ``restore_depth`` on numpy / (H,W) / uint16 / uint8 input; a model saved and loaded again;
* one backward through a trainable model (the gradient of every parameter, keyed by name, and of the input):
  the defaults and ``paper`` with 3 layers, every shipped model with its own layers (``trainable=True``);
* the structure of every model: ``state_dict`` keys, shapes and values, the parameters in order, and which
  require grad frozen and trainable;

and writes everything to one file; ``compare`` reports every difference (values, dtypes, shapes, missing keys).

Config API: field overrides are given as version-1 flat dicts (the field names of ``RestorerConfig`` at 046c797) and
built with ``RestorerConfig.from_dict(flat)``, which the new code promises to accept (converting with exactly the
defaults); if a partial dict is refused the full version-1 default dict below fills it up.

    python check.py run OUT.pt          # with the package on PYTHONPATH (one CPU thread)
    python check.py compare BASE.pt NEW.pt
    python check.py both BASE_ROOT NEW_ROOT   # runs both (PYTHONPATH=each root), then compares
"""
from __future__ import annotations

import copy
import os
import subprocess
import sys
import tempfile
import time

import torch
import torch.nn.functional as F

# Parameter/state keys renamed by a refactor, new name -> base name, so that the compare matches them (issue 10 had
# "block_matcher.log_temperature" -> "log_temperature"). Empty: at 046c797 every key is as the refactor finds it.
_RENAMED: dict = {}

SHIPPED = ("denoise", "denoise-guided", "denoise-refined", "upsample", "upsample-area", "upsample-x4",
           "upsample-x4-refined")
NAMED = ("default", "fast", "paper", "tv", "tv+nl")

# The named configurations at 046c797 as version-1 flat overrides of the defaults (config.py ABLATIONS / PRESETS).
V1_NAMED = {
    "default": {},
    "fast": dict(search_window=11, k=10, nl_value_weight_clean=0.0, upsample_search_window=11, match_layers=[2]),
    "paper": dict(use_nonlocal=True, use_outliers=True, use_singular=True, block_size=5, search_window=21, k=10,
                  rematch="exact", init_fill="pushpull", guided_prior=0.0, singular_support=0,
                  singular_line_support=False, singular_gate=0.0, fidelity_band=0.0, nl_value_weight=0.0),
    "tv": dict(use_nonlocal=False, use_outliers=False, use_singular=False, fidelity_band=0.0, nl_value_weight=0.0),
    "tv+nl": dict(use_nonlocal=True, use_outliers=False, use_singular=False, fidelity_band=0.0, nl_value_weight=0.0),
}

# dataclasses.asdict(RestorerConfig()) at 046c797: the version-1 defaults, used only if from_dict refuses a partial dict
V1_DEFAULTS = {
    "block_size": 3, "cg_fixed_iters": [5, 4, 3, 3, 3, 2, 2, 1], "cg_max_iter": 50, "cg_tol": 0.001,
    "color_weight": 400.0, "degradation": "area", "eta": 2.0, "eta_clean": 0.25, "extra": {}, "fidelity_band": 4.0,
    "gamma": 3.0, "guidance_channels": 16, "guidance_net": False, "guidance_range": 4.0, "guided_prior": 3.2,
    "implicit_backward": False, "include_self": False, "init_dt_iterations": 1, "init_dt_sigma_color": 0.2,
    "init_dt_sigma_space": 6.0, "init_fill": "domain", "init_keep_observed": True, "init_kernel_size": 11,
    "init_sigma_color": 0.025, "init_sigma_space": 6.0, "init_singular": False, "isotropic": False, "k": 40,
    "lam": 1.0, "match_layers": [2, 5], "mu1": 2.0, "mu2": 0.5, "nl_value_offset": 6.0, "nl_value_range": 3.0,
    "nl_value_range_clean": 1.0, "nl_value_ridge": 1.0, "nl_value_var": 0.25, "nl_value_weight": 10.0,
    "nl_value_weight_clean": 30.0, "num_layers": 8, "precondition": True, "prior_on_singular": True,
    "refine_channels": 32, "refine_layers": 6, "refine_net": False, "refine_task": "upsample", "rematch": "refine",
    "rematch_lattice": 2, "search_window": 15, "singular_gate": 0.002, "singular_line_support": True,
    "singular_rounds": 3, "singular_sigma_floor": 2.5, "singular_support": 3, "singular_support_tol": 2.0,
    "singular_tau": 0.5, "snap_radius": 2, "snap_refit_band": 1.5, "snap_refit_edge": 2.0, "snap_refit_radius": 5,
    "snap_rounds": 1, "snap_share": 0.6, "snap_sigma_color": 0.235, "snap_sigma_space": 0.0, "temperature": 0.5,
    "upsample_init": "jbu", "upsample_init_band": 3.0, "upsample_init_consistency": 2.0,
    "upsample_init_edge_band": 0.5,
    "upsample_jbu": {"first_order": True, "radius": 2, "sigma_color": 0.1, "sigma_space": 1.0}, "upsample_k": 10,
    "upsample_output_band": 3.0, "upsample_output_edge": 1.0, "upsample_output_edge_threshold": 16.0,
    "upsample_scale": {"mu1": 3.0, "mu2": 3.0}, "upsample_search_window": 21, "upsample_tv_per_factor": True,
    "use_nonlocal": True, "use_outliers": True, "use_singular": True,
}

# the task inputs: (name, factor, degradation, holes); "outliers" = holes + impulses + flying pixels (denoising)
DENOISE_INPUTS = (("denoise/full", 1, "area", "none"), ("denoise/holes", 1, "area", "holes"),
                  ("denoise/outliers", 1, "area", "outliers"))
UPSAMPLE_INPUTS = tuple((f"x{f}/{deg}/{tag}", f, deg, tag) for f in (2, 4) for deg in ("area", "bicubic")
                        for tag in ("none", "holes"))
ALL_INPUTS = DENOISE_INPUTS + UPSAMPLE_INPUTS
# the inputs each shipped model was made for (upsample-x4's config.json has no degradation: area, its default)
OWN_UPSAMPLING = {"upsample": "x4/bicubic/holes", "upsample-area": "x4/area/holes", "upsample-x4": "x4/area/holes",
                  "upsample-x4-refined": "x4/bicubic/holes"}


# ---- inputs ------------------------------------------------------------------------------------------------------
def _inputs(factor: int, degradation: str, holes: str, dtype=torch.float32, size=(64, 80)):
    """Two seeded synthetic scenes, the low-resolution depth (area or antialiased bicubic), sigma = 3 noise."""
    from torch_depth_sr.datasets.synthetic import make_scene

    scenes = [make_scene(*size, seed=s) for s in (0, 1)]
    gt = torch.stack([s["gt"] for s in scenes]).to(dtype)
    rgb = torch.stack([s["rgb"] for s in scenes]).to(dtype)
    if factor > 1:
        h, w = gt.shape[-2] // factor, gt.shape[-1] // factor
        lr = (F.avg_pool2d(gt, factor) if degradation == "area" else
              F.interpolate(gt, size=(h, w), mode="bicubic", antialias=True, align_corners=False))
    else:
        lr = gt
    g = torch.Generator().manual_seed(1234 + factor)
    noisy = lr + 3.0 * torch.randn(lr.shape, generator=g, dtype=torch.float64).to(dtype)
    if holes in ("holes", "outliers"):
        h, w = noisy.shape[-2:]
        noisy[0, :, h // 4: h // 4 + max(2, h // 8), w // 3: w // 3 + max(2, w // 6)] = 0
        noisy[1, :, h // 2: h // 2 + max(2, h // 10), 2: 2 + max(2, w // 8)] = 0
    if holes == "outliers":  # impulses anywhere, flying pixels (the mean of both sides) on depth edges
        g2 = torch.Generator().manual_seed(99)
        b, _, h, w = noisy.shape
        idx = torch.randint(0, h * w, (b, 12), generator=g2)
        sign = torch.randint(0, 2, (b, 12), generator=g2).to(dtype) * 2 - 1
        flat = noisy.view(b, -1)
        for i in range(b):
            flat[i, idx[i]] = (flat[i, idx[i]] + 40 * sign[i]).clamp_min(1.0)
        edge = (lr[..., :, 2:] - lr[..., :, :-2]).abs() > 20  # (B,1,h,w-2): a jump between the neighbours
        for i in range(b):
            where = edge[i, 0].nonzero()[::7][:10]
            for r, c in where.tolist():
                noisy[i, 0, r, c + 1] = 0.5 * (lr[i, 0, r, c] + lr[i, 0, r, c + 2])
    return noisy.clamp_min(0), rgb


# ---- building models ---------------------------------------------------------------------------------------------
def _config(flat: dict):
    """A config from version-1 flat fields (overrides of the defaults)."""
    from torch_depth_sr import RestorerConfig

    flat = copy.deepcopy(dict(flat))
    try:
        return RestorerConfig.from_dict(flat)
    except Exception:  # a partial version-1 dict refused: give it whole
        return RestorerConfig.from_dict({**copy.deepcopy(V1_DEFAULTS), **flat})


def _model(flat: dict | None = None, trainable: bool = False):
    from torch_depth_sr import DepthRestorer

    return DepthRestorer(_config(flat or {}), trainable=trainable)


def _build(name: str):
    """A named configuration: ``from_preset`` on the new code, ``ablation`` / ``preset`` on the base."""
    from torch_depth_sr import DepthRestorer

    if hasattr(DepthRestorer, "from_preset"):
        return DepthRestorer.from_preset(name)
    if name == "default":
        return DepthRestorer()
    if name == "fast":
        return DepthRestorer.preset("fast")
    return DepthRestorer.ablation(name)


def _pretrained(name: str, trainable: bool = False):
    from torch_depth_sr import DepthRestorer

    return DepthRestorer.from_pretrained(name, trainable=trainable)


# ---- recording ---------------------------------------------------------------------------------------------------
def _info(info: dict) -> dict:
    out = {}
    for k, v in sorted(info.items()):
        if k == "seconds":
            continue
        try:
            out[f"info.{k}"] = torch.tensor(v, dtype=torch.float64 if k in ("noise_sigma", "scale", "offset") else None)
        except (TypeError, ValueError):
            out[f"info.{k}"] = repr(v)
    return out


def _details(model, depth, rgb, **kw):
    try:
        return _details_or_raise(model, depth, rgb, **kw)
    except Exception as exc:  # recorded: the new code must fail the same way (e.g. float64 through the CNNs at 046c797)
        return {"error": f"{type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc).strip() else ''}"}


def _details_or_raise(model, depth, rgb, **kw):
    if hasattr(model, "restore_with_details"):  # forward returns the depth only; the details give the rest
        r = model.restore_with_details(depth, rgb, **kw)
        plain = model(depth, rgb, **kw)  # forward gives the same depth as the details
        assert torch.equal(torch.nan_to_num(plain, nan=-1.0), torch.nan_to_num(r.depth, nan=-1.0))
    else:
        r = model(depth, rgb, return_details=True, **kw)
    return {"depth": r.depth, "confidence": r.confidence, "trusted": r.trusted, "outliers": r.outliers,
            **_info(r.info)}


def _layout_details(depth, rgb, model, **kw):
    """restore_depth on numpy / (H,W) / (1,H,W) / integer input: the layout handling outside the module."""
    import numpy as np
    from torch_depth_sr import restore_depth

    r = restore_depth(depth, rgb, model=model, return_details=True, **kw)

    def as_t(a):
        return a if isinstance(a, torch.Tensor) else torch.from_numpy(np.ascontiguousarray(a))

    return {"depth": as_t(r.depth), "confidence": as_t(r.confidence), "trusted": as_t(r.trusted),
            "outliers": as_t(r.outliers), **_info(r.info)}


def _structure(model) -> dict:
    """state_dict keys, shapes and values; the parameters in order; which require grad."""
    out = {f"state:{_RENAMED.get(k, k)}": v.detach().clone() for k, v in model.state_dict().items()}
    out["parameter_order"] = ",".join(_RENAMED.get(n, n) for n, _ in model.named_parameters())
    out["requires_grad"] = ",".join(sorted(_RENAMED.get(n, n) for n, p in model.named_parameters()
                                           if p.requires_grad))
    out["buffers"] = ",".join(_RENAMED.get(n, n) for n, _ in model.named_buffers())
    return out


def _backward(model, y, rgb) -> dict:
    y = y.clone().requires_grad_(True)
    out = model(y, rgb)
    out.square().mean().backward()
    grads = {f"grad:{_RENAMED.get(n, n)}": p.grad.clone() for n, p in model.named_parameters() if p.grad is not None}
    return {"out": out.detach(), "input_grad": y.grad.clone(),
            "with_grad": ",".join(sorted(_RENAMED.get(n, n) for n, p in model.named_parameters()
                                         if p.grad is not None)), **grads}


def run(path: str) -> None:
    import torch_depth_sr

    torch.set_num_threads(1)  # one thread: the same reduction order on any machine
    torch.manual_seed(0)
    t0 = time.perf_counter()
    print("package:", torch_depth_sr.__file__, file=sys.stderr)
    inputs = {name: _inputs(f, deg, holes) for name, f, deg, holes in ALL_INPUTS}
    inputs64 = {name: _inputs(f, deg, holes, torch.float64) for name, f, deg, holes in ALL_INPUTS
                if name in ("denoise/outliers", "x4/area/holes", "x2/bicubic/holes")}
    results: dict = {}

    def all_tasks(label, model, fill_trusted=("denoise/outliers", "x2/area/holes", "x4/bicubic/holes")):
        for name, (y, rgb) in inputs.items():
            results[f"{label}/{name}"] = _details(model, y, rgb)
        for name in fill_trusted:
            y, rgb = inputs[name]
            results[f"{label}/{name}/fill_trusted"] = _details(model, y, rgb, fill="trusted")
        for name, (y, rgb) in inputs64.items():
            results[f"{label}/{name}/float64"] = _details(model, y, rgb)

    # the defaults, every named configuration, every shipped model: every task input, fill="trusted", float64
    all_tasks("defaults", _model())
    results["structure/defaults"] = _structure(_model())
    results["structure/defaults/trainable"] = _structure(_model(trainable=True))
    for name in NAMED:
        all_tasks(f"named/{name}", _build(name))
        results[f"structure/named/{name}"] = _structure(_build(name))
        # the version-1 flat dict of the named configuration gives the same numbers
        y, rgb = inputs["denoise/outliers"]
        results[f"named/{name}/from_v1_dict/denoise/outliers"] = _details(_model(V1_NAMED[name]), y, rgb)
        y, rgb = inputs["x4/area/holes"]
        results[f"named/{name}/from_v1_dict/x4/area/holes"] = _details(_model(V1_NAMED[name]), y, rgb)
    for name in SHIPPED:
        all_tasks(f"shipped/{name}", _pretrained(name))
        results[f"structure/shipped/{name}"] = _structure(_pretrained(name))
        results[f"structure/shipped/{name}/trainable"] = _structure(_pretrained(name, trainable=True))
    # a model saved and loaded again (config.json in whatever form the code writes it)
    with tempfile.TemporaryDirectory() as tmp:
        from torch_depth_sr import DepthRestorer

        for label, model in (("defaults", _model()), ("paper", _build("paper")),
                             ("denoise-refined", _pretrained("denoise-refined"))):
            model.save(os.path.join(tmp, label))
            loaded = DepthRestorer.load(os.path.join(tmp, label))
            for name in ("denoise/outliers", "x4/bicubic/holes"):
                y, rgb = inputs[name]
                results[f"saved/{label}/{name}"] = _details(loaded, y, rgb)
    # the issue-10 cases: explicit field overrides (version-1 flat fields)
    for tag in ("none", "holes"):
        y, rgb = inputs[f"denoise/{'full' if tag == 'none' else tag}"]
        key = f"override/denoise/{tag}"
        results[f"{key}/init_singular"] = _details(_model({"init_singular": True}), y, rgb)
        results[f"{key}/no_guided_prior_on_singular"] = _details(
            _model({"prior_on_singular": False, "init_keep_observed": False}), y, rgb)
        results[f"{key}/jbf_exact_converged"] = _details(
            _model({"init_fill": "jbf", "rematch": "exact", "cg_fixed_iters": []}), y, rgb)
        results[f"{key}/no_guide"] = _details(_model(), y, None)
        results[f"{key}/isotropic_implicit"] = _details(_model({"isotropic": True, "implicit_backward": True}), y, rgb)
        results[f"{key}/guidance_net_untrained"] = _details(_model({"guidance_net": True}), y, rgb)
        y64, rgb64 = _inputs(1, "area", tag, torch.float64)
        results[f"{key}/float64_3layers"] = _details(_model({"num_layers": 3}), y64, rgb64)
        for factor in (2, 4):
            for deg in ("area", "bicubic"):
                y, rgb = inputs[f"x{factor}/{deg}/{tag}"]
                key = f"override/x{factor}/{deg}/{tag}"
                results[f"{key}/degradation"] = _details(_model({"degradation": deg}), y, rgb)
                results[f"{key}/degradation/fill_trusted"] = _details(_model({"degradation": deg}), y, rgb,
                                                                      fill="trusted")
                results[f"{key}/bicubic_init"] = _details(_model(
                    {"degradation": deg, "upsample_init": "bicubic", "upsample_tv_per_factor": False,
                     "upsample_scale": {"lam": 2.0}, "upsample_jbu": {"radius": 3}}), y, rgb)
                results[f"{key}/paper"] = _details(_model({**V1_NAMED["paper"], "degradation": deg}), y, rgb)
                results[f"{key}/fast"] = _details(_model({**V1_NAMED["fast"], "degradation": deg}), y, rgb)
    # restore_depth: the layouts, dtypes and array types it converts (numpy, (H,W), (1,H,W), uint16, uint8 colour)
    small = _model({"num_layers": 3})
    for tag in ("full", "holes"):
        y, rgb = inputs[f"denoise/{tag}"]
        d_np, rgb_np = y[0, 0].numpy(), (rgb[0].permute(1, 2, 0) * 255).round().to(torch.uint8).numpy()
        u16 = (y[0, 0] * 10).round().numpy().astype("uint16")
        results[f"layout/{tag}/numpy_hw"] = _layout_details(d_np, rgb_np, small)
        results[f"layout/{tag}/numpy_hw_trusted"] = _layout_details(d_np, rgb_np, small, fill="trusted")
        results[f"layout/{tag}/uint16"] = _layout_details(u16, rgb_np, small)
        results[f"layout/{tag}/uint16_trusted"] = _layout_details(u16, rgb_np, small, fill="trusted")
        results[f"layout/{tag}/torch_chw"] = _layout_details(y[0], rgb[0], small)
        yl, rgbl = inputs[f"x2/area/{'none' if tag == 'full' else tag}"]
        results[f"layout/{tag}/x2_numpy_hw"] = _layout_details(yl[1, 0].numpy(), rgbl[1].numpy(), small)
    # one backward through a trainable model: gradients of every parameter (by name) and of the input
    grad_inputs = {name: _inputs(f, deg, holes, size=(48, 64)) for name, f, deg, holes in ALL_INPUTS
                   if name in ("denoise/outliers", "x2/area/holes", "x2/bicubic/holes", "x4/area/holes",
                               "x4/bicubic/holes")}
    for name in ("default", "paper"):
        for task in ("denoise/outliers", "x2/area/holes", "x2/bicubic/holes"):
            deg = "bicubic" if "bicubic" in task else "area"
            model = _model({**V1_NAMED[name], "num_layers": 3, "degradation": deg}, trainable=True)
            results[f"grad/{name}/3layers/{task}"] = _backward(model, *grad_inputs[task])
    for name in SHIPPED:
        for task in ("denoise/outliers", OWN_UPSAMPLING.get(name, "x4/area/holes")):
            results[f"grad/shipped/{name}/{task}"] = _backward(_pretrained(name, trainable=True), *grad_inputs[task])
    torch.save(results, path)
    print(f"{len(results)} cases -> {path} in {time.perf_counter() - t0:.0f} s", file=sys.stderr)


# ---- comparing ---------------------------------------------------------------------------------------------------
def _diff(ta, tb) -> str | float | None:
    """None when identical; a float max abs diff when the values differ; a string when the kind/shape differs."""
    if not isinstance(ta, torch.Tensor) or not isinstance(tb, torch.Tensor):
        return None if (type(ta) is type(tb) and ta == tb) else f"{ta!r:.60} != {tb!r:.60}"
    if ta.shape != tb.shape:
        return f"shape {tuple(ta.shape)} != {tuple(tb.shape)}"
    if ta.dtype != tb.dtype:
        return f"dtype {ta.dtype} != {tb.dtype}"
    if ta.numel() == 0 or torch.equal(ta, tb):
        return None
    if ta.is_floating_point():
        na, nb = ta.isnan(), tb.isnan()
        if not torch.equal(na, nb):
            return f"NaN at {int((na != nb).sum())} different places"
        if torch.equal(ta[~na], tb[~nb]):
            return None
        return (ta[~na].double() - tb[~nb].double()).abs().max().item()
    return float((ta.long() - tb.long()).abs().max().item())


def compare(a_path: str, b_path: str, verbose: bool = True) -> int:
    a, b = torch.load(a_path, weights_only=False), torch.load(b_path, weights_only=False)
    worst, bad, bad_cases = 0.0, 0, 0
    for case in sorted(set(a) | set(b)):
        if case not in a or case not in b:
            print(f"{case:60s} only in {'base' if case in a else 'new'}")
            bad += 1
            bad_cases += 1
            continue
        diffs = []
        for key in sorted(set(a[case]) | set(b[case])):
            if key not in a[case] or key not in b[case]:
                diffs.append(f"{key}: only in {'base' if key in a[case] else 'new'}")
                bad += 1
                continue
            d = _diff(a[case][key], b[case][key])
            if d is None:
                continue
            bad += 1
            if isinstance(d, float):
                worst = max(worst, d)
                diffs.append(f"{key}: {d:.3g}")
            else:
                diffs.append(f"{key}: {d}")
        bad_cases += bool(diffs)
        if verbose or diffs:
            print(f"{case:60s} {'identical' if not diffs else '; '.join(diffs)}")
    n = len(set(a) | set(b))
    print(f"\n{n} cases, {bad_cases} differ; max abs diff over every tensor: {worst:g}; {bad} entries differ")
    return 1 if bad else 0


def both(base_root: str, new_root: str) -> int:
    paths = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, root in (("base", base_root), ("new", new_root)):
            out = os.path.join(tmp, f"{label}.pt")
            env = {**os.environ, "PYTHONPATH": os.path.abspath(root), "OMP_NUM_THREADS": "1"}
            t0 = time.perf_counter()
            subprocess.run([sys.executable, os.path.abspath(__file__), "run", out], env=env, check=True, cwd=tmp)
            print(f"{label}: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
            paths.append(out)
        return compare(*paths)


if __name__ == "__main__":
    cmd, *args = sys.argv[1:] or ["help"]
    if cmd == "run":
        run(*args)
    elif cmd == "compare":
        quiet = "-q" in args
        sys.exit(compare(*[a for a in args if a != "-q"], verbose=not quiet))
    elif cmd == "both":
        sys.exit(both(*args))
    else:
        sys.exit(__doc__)
