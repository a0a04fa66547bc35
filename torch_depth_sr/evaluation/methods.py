"""The methods a benchmark compares, behind one call: ``run_method(name, sample) -> (1,1,H,W)``.

Baseline parameters are the ones fitted on the Middlebury 2006 scenes (see ``tune.py`` and the
README); the model's come from :class:`~torch_depth_sr.RestorerConfig` defaults, fitted the same way.
"""
from __future__ import annotations

import json
from functools import lru_cache
from typing import Optional

import torch

from ..fill import fill_holes

__all__ = [
    "DENOISE_METHODS",
    "UPSAMPLE_METHODS",
    "JBF_PARAMS",
    "JBF_TRACK_PARAMS",
    "JBU_PARAMS",
    "DICTIONARY_PARAMS",
    "PRESET_OF",
    "RGF_PARAMS",
    "SHIPPED",
    "TAKES_PRETRAINED",
    "TIER_METHODS",
    "run_method",
]

DENOISE_METHODS = ("input", "jbf", "rgf", "dictionary", "tv", "tv+nl", "full")
UPSAMPLE_METHODS = ("bicubic", "jbf", "tv", "tv+nl", "full")

# The `jbf` denoising baseline (`baselines.jbf.jbf_denoise`: mask-normalised JBF, σc in grey levels of the 0-255
# colour, OpenCV's window radius round(1.5 σs)), fitted per track on the full 2006 images by
# `python -m torch_depth_sr.evaluation.tune_jbf` (grids in `tune_jbf.GRIDS`; best mean RMSE paper 1.804,
# sensor 2.290). `paper`: one pass; `sensor`: passes with median-based outlier rejection.
JBF_TRACK_PARAMS = {
    "paper": dict(sigma_space=2.5, sigma_color=10.0, iterations=1, reject=None, color_distance_type="l2"),
    "sensor": dict(sigma_space=2.5, sigma_color=20.0, iterations=2, reject=20.0, color_distance_type="l1"),
}
# The `paper` setting as `joint_bilateral_filter` arguments (one pass; the speed benchmark times it).
JBF_PARAMS = dict(kernel_size=2 * round(1.5 * JBF_TRACK_PARAMS["paper"]["sigma_space"]) + 1,
                  sigma_space=JBF_TRACK_PARAMS["paper"]["sigma_space"],
                  sigma_color=JBF_TRACK_PARAMS["paper"]["sigma_color"] / 255.0,
                  color_distance_type=JBF_TRACK_PARAMS["paper"]["color_distance_type"])
JBU_PARAMS = dict(sigma_space=1.0, sigma_color=0.1)
DICTIONARY_PARAMS = dict(patch_size=8, n_atoms=128, stride=4)
# Fitted per track on the full 2006 images by `python -m torch_depth_sr.evaluation.tune_rgf` (grid σs {2, 3, 5}
# × σc {3, 5, 7, 10, 20} × iterations {2, 3, 4}; best RMSE paper 0.848, sensor 4.441 — the sensor optimum lies
# on the grid's edge: a self-guided filter keeps flying pixels, and no setting makes it a sensor method).
RGF_PARAMS = {"paper": dict(sigma_space=3.0, sigma_color=7.0, iterations=3),
              "sensor": dict(sigma_space=3.0, sigma_color=20.0, iterations=4)}


# the methods that run shipped parameters (``from_pretrained(name)``): "trained-guided" with the guidance network's
# per-pixel thresholds, "trained-refined" that model plus the edge refiner of denoising, "trained-upsample" the frozen
# model plus the edge refiner at every factor, "trained-upsample-area" the same for area-downsampled noisy input
# (the Park et al. inputs of upsample-b; issue 14)
SHIPPED = {"trained": "denoise", "trained-guided": "denoise-guided", "trained-refined": "denoise-refined",
           "trained-x4": "upsample-x4", "trained-upsample": "upsample", "trained-upsample-area": "upsample-area"}
# those of them that load a saved candidate instead when ``pretrained`` is given
TAKES_PRETRAINED = ("trained", "trained-refined", "trained-x4", "trained-upsample", "trained-upsample-area")
_MODEL_METHODS = ("tv", "tv+nl", "full", "fast", "default", "best", "full-fast", "paper-model", *SHIPPED)


# the model methods' named configurations (``DepthRestorer.from_preset``); the speed tiers (issue 27) are ``fast``,
# ``default`` and ``best``; ``full`` is the frozen configuration's defaults (the default tier until 2026-12-04),
# ``full-fast`` the former name of ``fast``
PRESET_OF = {"tv": "tv", "tv+nl": "tv+nl", "full": "full", "fast": "fast", "default": "default", "best": "best",
             "full-fast": "fast", "paper-model": "paper"}
TIER_METHODS = {"fast": "fast", "default": "default", "best": "best"}  # tier name -> bench method


@lru_cache(maxsize=None)
def _model(name: str, device: str, overrides: str = "{}", pretrained: Optional[str] = None):
    from ..config import TRAINED_PRESETS, apply_overrides, preset_config
    from ..model import DepthRestorer

    if pretrained is not None:  # a candidate before it ships (run_method passes it to TAKES_PRETRAINED only)
        return DepthRestorer.load(pretrained).to(device)
    if name in SHIPPED:
        return DepthRestorer.from_pretrained(SHIPPED[name]).to(device)
    # "paper-model": the paper's model without the library's extensions (preset "paper")
    preset = PRESET_OF[name]
    if preset in TRAINED_PRESETS:  # a speed tier that carries trained parameters
        model = DepthRestorer.from_preset(preset)
        changes = json.loads(overrides)
        if changes:
            trained = model.state_dict()
            model = DepthRestorer(apply_overrides(model.config, changes))
            model.load_state_dict(trained)
        return model.to(device)
    return DepthRestorer(apply_overrides(preset_config(preset), json.loads(overrides))).to(device)


def run_method(name: str, sample: dict, device: str = "cpu", config: Optional[dict] = None,
               track: Optional[str] = None, pretrained: Optional[str] = None) -> torch.Tensor:
    """Run ``name`` on a sample dict (``depth (1,h,w)``, ``rgb (3,H,W)``, optional ``factor``).

    ``config``: :class:`~torch_depth_sr.RestorerConfig` overrides for the model methods (``tv``, ``tv+nl``,
    ``full``, ``fast``, ``best``, ``full-fast``, ``paper-model``: :data:`PRESET_OF`), applied to the method's preset by
    :func:`~torch_depth_sr.config.apply_overrides`, e.g. ``{"block_matching": {"block_size": 5}}`` (or the
    version-1 ``{"block_size": 5}``); the shipped ``trained`` parameters and the baselines ignore it.
    ``track``: the benchmark track; ``jbf`` and ``rgf`` have settings fitted per track (``paper`` when not given).
    ``pretrained``: a folder written by :meth:`~torch_depth_sr.DepthRestorer.save` (a training run's ``best``) that
    ``trained``, ``trained-x4`` and ``trained-upsample`` load instead of the shipped parameters.
    """
    y = sample["depth"][None].to(device)
    rgb = sample["rgb"][None].to(device)
    factor = int(sample.get("factor", 1) or 1)
    mask = (y > 0).float()
    with torch.no_grad():
        if name == "input":
            return fill_holes(y, mask)
        if name == "bicubic":
            from ..baselines import bicubic_upsample

            return bicubic_upsample(fill_holes(y, mask), factor)
        if name == "jbf":
            from ..baselines import jbf_denoise, joint_bilateral_upsample

            if factor > 1:
                return joint_bilateral_upsample(y, rgb, factor, **JBU_PARAMS)
            return jbf_denoise(y, rgb, mask, **JBF_TRACK_PARAMS.get(track or "paper", JBF_TRACK_PARAMS["paper"]))
        if name == "rgf":
            from ..baselines import rolling_guidance_filter

            if factor > 1:
                raise ValueError("rgf is a denoising baseline; it does not upsample.")
            return rolling_guidance_filter(y, mask, **RGF_PARAMS.get(track or "paper", RGF_PARAMS["paper"]))
        if name == "kornia-jbf9":  # kornia's 9x9 joint bilateral blur as users call it (bench --track speed's
            # reference), on the depth with its holes pulled-pushed first
            import kornia

            return kornia.filters.joint_bilateral_blur(fill_holes(y, mask), rgb, (9, 9), 0.1, (3.0, 3.0))
        if name == "dictionary":
            from ..baselines import dictionary_denoise

            return dictionary_denoise(y, rgb, mask, **DICTIONARY_PARAMS)
        if name in _MODEL_METHODS:
            return _model(name, device, json.dumps(config or {}, sort_keys=True),
                          pretrained if name in TAKES_PRETRAINED else None)(y, rgb)
    extra = [m for m in (*_MODEL_METHODS, "kornia-jbf9") if m not in DENOISE_METHODS + UPSAMPLE_METHODS]
    raise ValueError(f"unknown method {name!r}; allowed are {sorted(set(DENOISE_METHODS + UPSAMPLE_METHODS))} "
                     f"and {extra}.")
