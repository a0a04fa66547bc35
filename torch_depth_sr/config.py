"""Settings of the restoration model (all thresholds in multiples of the noise level; see ``noise.py``)."""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field


@dataclass
class RestorerConfig:
    """Every setting of :class:`~torch_depth_sr.DepthRestorer`, JSON-serialisable.

    Units: depth is normalised by the estimated noise level (scale policy in ``noise.py``),
    so ``lam``, ``eta``, ``gamma`` and ``singular_sigma_floor`` are in noise-σ units, and
    ``temperature`` is in σ² per block pixel.
    """

    num_layers: int = 8
    # initial values of each layer's parameters (softplus-positive when trainable)
    lam: float = 1.0  # λ: TV weight
    eta: float = 2.0  # η: nonlocal-gradient weight
    gamma: float = 3.0  # γ: sparse outlier threshold
    mu1: float = 2.0  # μ₁: splitting weight for z ≈ Dx
    mu2: float = 0.5  # μ₂: splitting weight for w ≈ Dx − α
    isotropic: bool = False  # isotropic (group) TV shrinkage instead of anisotropic
    # initial estimate x⁰: "jbf" (colour-guided normalised convolution: masked joint bilateral filter,
    # remaining holes by push-pull) or "pushpull" (push-pull normalised convolution only)
    init_fill: str = "jbf"
    # β: untrusted pixels (missing or singular) are pulled with weight β to the colour-guided estimate
    # instead of being left to the regularisers alone (an extension of the paper; 0 = the paper's model)
    guided_prior: float = 3.2
    prior_on_singular: bool = True  # β also on pixels the singular test rejects (else on missing pixels only)
    init_singular: bool = False  # Q⁰ by the singular test against the guided estimate (else Q⁰ = measured)
    init_keep_observed: bool = True  # x⁰ keeps the measured values; the guided filter fills only the holes
    init_kernel_size: int = 11
    init_sigma_space: float = 6.0
    init_sigma_color: float = 0.025
    # guided upsampling: x⁰ by joint bilateral upsampling ("jbu") or "bicubic"; the TV weight λ is divided by
    # the factor s (TV of an s-times finer grid grows like s for the same surface; the quadratic terms do not)
    upsample_init: str = "jbu"
    upsample_jbu: dict = field(default_factory=lambda: {"radius": 2, "sigma_space": 1.0, "sigma_color": 0.1})
    upsample_tv_per_factor: bool = True
    # guided upsampling: multipliers on the layer parameters named here (λ, η, γ, μ₁, μ₂). The data term
    # weighs each fine pixel by 1/s² (KᵀK), so the half-quadratic splitting needs larger μ to hold Dx to its
    # shrunk copies; fitted on the 2006 scenes area-downsampled by 2 and 4 with σ = 5 noise (README).
    upsample_scale: dict = field(default_factory=lambda: {"mu1": 3.0, "mu2": 3.0})
    # terms (ablations: tv = all False; tv+nl = use_nonlocal only)
    use_nonlocal: bool = True
    use_outliers: bool = True
    use_singular: bool = True
    # block matching
    block_size: int = 3  # the paper uses 5×5; 3×3 fitted better on the 2006 scenes (README, "Model choices")
    search_window: int = 21
    k: int = 10
    color_weight: float = 400.0  # ρ: colour distance weight (colour in [0,1])
    temperature: float = 0.5  # h: weight temperature
    include_self: bool = False
    match_layers: tuple = (2, 5)  # layers that redo block matching on the current x (it always runs once on x⁰)
    # singular pixel detection
    singular_tau: float = 0.5
    singular_sigma_floor: float = 2.5
    singular_rounds: int = 3
    singular_gate: float = 0.002  # a sample whose share of gross failures is below this keeps Q = measured (0 = off)
    # linear solves
    cg_tol: float = 1e-3
    cg_max_iter: int = 50
    precondition: bool = True
    implicit_backward: bool = False
    extra: dict = field(default_factory=dict)

    def __post_init__(self):
        bad = set(self.upsample_scale) - {"lam", "eta", "gamma", "mu1", "mu2"}
        if bad or any(not float(v) > 0 for v in self.upsample_scale.values()):
            raise ValueError(f"upsample_scale must map layer parameters ['eta', 'gamma', 'lam', 'mu1', 'mu2'] to "
                             f"positive multipliers; got {self.upsample_scale!r}.")

    def replace(self, **changes) -> "RestorerConfig":
        return dataclasses.replace(self, **changes)

    def to_json(self) -> str:
        return json.dumps(dataclasses.asdict(self), indent=2, sort_keys=True)

    @classmethod
    def from_dict(cls, d: dict) -> "RestorerConfig":
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"unknown RestorerConfig keys {sorted(unknown)}; allowed are {sorted(known)}.")
        d = dict(d)
        if "match_layers" in d:
            d["match_layers"] = tuple(d["match_layers"])
        return cls(**d)


ABLATIONS = {
    "tv": dict(use_nonlocal=False, use_outliers=False, use_singular=False),
    "tv+nl": dict(use_nonlocal=True, use_outliers=False, use_singular=False),
    "full": dict(use_nonlocal=True, use_outliers=True, use_singular=True),
}

# Speed presets: settings that trade a measured amount of accuracy for time (README, "Speed and memory").
# "fast": an 11×11 search window and one re-match (layer 2) instead of 21×21 and two; on the full 2006
# scenes RMSE +0.7 % (paper) and +0.9 % (sensor), about half the time at 640×480.
PRESETS = {
    "fast": dict(search_window=11, match_layers=(2,)),
}
