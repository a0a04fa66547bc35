"""Named configurations, reached through :meth:`DepthRestorer.from_preset(name) <torch_depth_sr.DepthRestorer.from_preset>`
(trained models through ``from_pretrained``). Each of :data:`PRESETS` is a set of changes to the defaults; each of
:data:`TRAINED_PRESETS` names a shipped model that ``from_preset`` loads (the speed tiers ``fast``, ``default`` and
``best``: :data:`TIERS`). Their measured accuracy and time are in ``docs/model-choices/`` and ``docs/speed.md``."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from .restorer import RestorerConfig

__all__ = ["PRESETS", "TIERS", "TRAINED_PRESETS", "preset_config"]

# what the paper's model leaves out: the library's extensions of the objective and its post-steps
_NO_EXTENSIONS = dict(value_prior=None, guided_prior=None, fidelity=None, clean_samples=None, edge_snap=None,
                      edge_refit=None)

PRESETS: dict[str, dict[str, Any]] = {
    # the configuration's defaults, frozen (no trained parameter), every extension on: what restore_depth(depth, rgb)
    # ran until 2026-12-04 and what guided upsampling still runs; the bench method "full"
    "full": {},
    # the paper's model as it stands (model.md): 5×5 blocks, 21×21 window, k = 10, exact re-matching, x⁰ = y with
    # its holes pulled-pushed, the singular test without the library's support rules and gate. Weights stay in
    # noise-σ units, CG keeps its fixed schedule, and guided upsampling (which the paper does not model) keeps the
    # library's x⁰ and output hold.
    "paper": dict(block_matching=dict(block_size=5, search_window=21, k=10, rematch="exact"),
                  initial=dict(fill="pushpull"), sided_fill=None,
                  singular=dict(support=0, line_support=False, gate=None), **_NO_EXTENSIONS),
    # ablations of the paper's terms; without the singular test every measurement counts as trusted, so the
    # fidelity band (which relies on it) is off too
    "tv": dict(terms=(), value_prior=None, fidelity=None),
    "tv+nl": dict(terms=("nonlocal",), value_prior=None, fidelity=None),
}


# Named configurations that carry trained parameters: ``DepthRestorer.from_preset(name)`` loads the shipped model
# ``from_pretrained(TRAINED_PRESETS[name])`` (issue 27's speed tiers, docs/speed.md "Speed tiers"):
# "fast": 2 layers trained end to end, one block-matching pass on x⁰ (7×7 window, 10 matches), 2 singular-test
#   rounds, a 7×7 x⁰ filter, edge snapping near depth edges only, then a trained edge refiner (16 channels, 3
#   layers); about a tenth of the frozen "full"'s time at 640×480 ("denoise-fast2"; "denoise-fast", 3 layers,
#   until 2026-12-05, is the stream's model);
# "default": what restore_depth(depth, rgb) runs to denoise: the guidance CNN's per-pixel thresholds of
#   "denoise-guided" with a 7×7 search window, then a 24-channel edge refiner; more accurate than "full" and about a
#   third of its time;
# "best": the best shipped denoiser: "denoise-refined" (the guidance CNN's per-pixel thresholds and the edge refiner)
#   with its refiner fine-tuned on near-clean noise as well, so that a near-clean map does not come out worse.
TRAINED_PRESETS: dict[str, str] = {"fast": "denoise-fast2", "default": "denoise-default", "best": "denoise-best"}

# the speed tiers, fastest first: what each name is, for users choosing by time (docs/speed.md)
TIERS = ("fast", "default", "best")


def preset_config(name: str, **overrides: Any) -> RestorerConfig:
    """The configuration named ``name`` (:data:`PRESETS`, or the ``config.json`` of the shipped model a name of
    :data:`TRAINED_PRESETS` loads), then ``overrides`` (as :meth:`RestorerConfig.replace`). The trained parameters
    of those come only with :meth:`DepthRestorer.from_preset <torch_depth_sr.DepthRestorer.from_preset>`.

    Examples:
        >>> preset_config("paper").block_matching.block_size
        5
        >>> preset_config("fast").num_layers
        2
    """
    if name in TRAINED_PRESETS:
        from .restorer import load_config_file

        return load_config_file(_PRETRAINED / TRAINED_PRESETS[name] / "config.json").replace(**overrides)
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; allowed are {sorted([*PRESETS, *TRAINED_PRESETS])} (other "
                         "trained models: DepthRestorer.from_pretrained).")
    return RestorerConfig().replace(**PRESETS[name]).replace(**overrides)


_PRETRAINED = Path(__file__).resolve().parents[1] / "pretrained"
