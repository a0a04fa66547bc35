"""Named configurations, reached through :meth:`DepthRestorer.from_preset(name) <torch_depth_sr.DepthRestorer.from_preset>`
(trained models through ``from_pretrained``). Each is a set of changes to the defaults; its measured accuracy and
time are in ``docs/model-choices/`` and ``docs/speed.md``."""
from __future__ import annotations

from typing import Any

from .restorer import RestorerConfig

__all__ = ["PRESETS", "preset_config"]

# what the paper's model leaves out: the library's extensions of the objective and its post-steps
_NO_EXTENSIONS = dict(value_prior=None, guided_prior=None, fidelity=None, clean_samples=None, edge_snap=None,
                      edge_refit=None)

PRESETS: dict[str, dict[str, Any]] = {
    # the defaults: what restore_depth(depth, rgb) runs
    "default": {},
    # the defaults before k = 40 (10 matches, the value prior's weight 10 on every sample) in an 11×11 window with
    # one re-match: about half the time at 640×480 (docs/speed.md)
    "fast": dict(block_matching=dict(search_window=11, k=10, upsample_search_window=11, match_layers=(2,)),
                 clean_samples=dict(value_weight=None)),
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


def preset_config(name: str, **overrides: Any) -> RestorerConfig:
    """The configuration named ``name`` (:data:`PRESETS`), then ``overrides`` (as :meth:`RestorerConfig.replace`).

    Examples:
        >>> preset_config("fast").block_matching.search_window
        11
    """
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; allowed are {sorted(PRESETS)} (trained models: "
                         "DepthRestorer.from_pretrained).")
    return RestorerConfig().replace(**PRESETS[name]).replace(**overrides)
