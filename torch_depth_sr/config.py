"""Settings of the restoration model (all thresholds in multiples of the noise level; see ``noise.py``)."""
from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from numbers import Integral, Real
from typing import TYPE_CHECKING, Any, Callable, ClassVar, Optional

from .errors import ModelFileError, ParameterError

if TYPE_CHECKING:  # hints only: the config stays importable without torch's operators
    import torch

    from .operators import Degradation

__all__ = [
    "ABLATIONS",
    "BlockMatchingConfig",
    "EdgeSnapConfig",
    "InitConfig",
    "JBUConfig",
    "LayerConfig",
    "LayerMultipliers",
    "PRESETS",
    "RefinerSettings",
    "RestorerConfig",
    "SIDED_FILL_DEFAULTS",
    "SidedFillConfig",
    "SingularConfig",
    "SolverConfig",
    "UpsamplingConfig",
    "ValuePriorConfig",
    "load_config_file",
]


@dataclass
class RestorerConfig:
    """Every setting of :class:`~torch_depth_sr.DepthRestorer`, JSON-serialisable.

    Units: depth is normalised by the estimated noise level (scale policy in ``noise.py``),
    so ``lam``, ``eta``, ``gamma`` and ``singular_sigma_floor`` are in noise-σ units, and
    ``temperature`` is in σ² per block pixel.

    The flat fields are the stored form (JSON files, ``RestorerConfig(**fields)``); each part of the model
    receives its own typed, frozen group instead of the whole config: :attr:`layer`, :attr:`block_matching`,
    :attr:`value_prior`, :attr:`singular`, :attr:`solver`, :attr:`initial`, :attr:`edge_snap` and :attr:`upsampling` (every field
    but ``num_layers``, ``fidelity_band`` and ``extra`` belongs to exactly one group).

    Examples:
        >>> c = RestorerConfig(singular_rounds=2)
        >>> c.singular.rounds, c.solver.iterations(9)
        (2, 1)
    """

    num_layers: int = 8
    # initial values of each layer's parameters (softplus-positive when trainable)
    lam: float = 1.0  # λ: TV weight
    eta: float = 2.0  # η: nonlocal-gradient weight
    # η is multiplied by this on samples whose singular test (its gate) finds no outliers, from the layer after the
    # first test on: there α (a mean over matched blocks) blurs edges more than it helps (1 = off)
    eta_clean: float = 0.25
    gamma: float = 3.0  # γ: sparse outlier threshold
    mu1: float = 2.0  # μ₁: splitting weight for z ≈ Dx
    mu2: float = 0.5  # μ₂: splitting weight for w ≈ Dx − α
    isotropic: bool = False  # isotropic (group) TV shrinkage instead of anisotropic
    # initial estimate x⁰, a colour-guided normalised convolution (remaining holes by pull-push): "domain" (masked
    # domain-transform filter, cost independent of the kernel area; init_dt_*), "jbf" (masked joint bilateral filter,
    # the former default; init_kernel_size, init_sigma_*) or "pushpull" (pull-push only, no colour)
    init_fill: str = "domain"
    # β: untrusted pixels (missing or singular) are pulled with weight β to the colour-guided estimate
    # instead of being left to the regularisers alone (an extension of the paper; 0 = the paper's model)
    guided_prior: float = 3.2
    prior_on_singular: bool = True  # β also on pixels the singular test rejects (else on missing pixels only)
    # per-pixel multipliers (in [1/R, R], R = guidance_range) of each layer's thresholds λ/μ₁, η/μ₂ and γ, predicted
    # by a small CNN from the colour image and the current estimate (torch_depth_sr.guidance; issue 14); off = the scalar model.
    # Zero-initialised, so an untrained network changes nothing; trained with the other parameters.
    guidance_net: bool = False
    guidance_channels: int = 16  # feature channels of the guidance network
    guidance_range: float = 4.0  # R: every multiplier of the guidance network lies in [1/R, R] (R = 1: all 1)
    # a learned residual CNN corrects the output at depth edges, clamped to the range of the measured values around
    # each pixel (torch_depth_sr.refiner; issue 14); zero-initialised, trained on the frozen model's outputs
    # (torch_depth_sr.training.refiner); off = the model alone. It runs for one task, the one it was trained for:
    # "upsample" (K ≠ I) or "denoise" (K = I, after the edge steps and before the fidelity band)
    refine_net: bool = False
    refine_channels: int = 32
    refine_layers: int = 6
    refine_task: str = "upsample"
    init_singular: bool = False  # Q⁰ by the singular test against the guided estimate (else Q⁰ = measured)
    init_keep_observed: bool = True  # x⁰ keeps the measured values; the guided filter fills only the holes
    init_kernel_size: int = 11
    init_sigma_space: float = 6.0
    init_sigma_color: float = 0.025  # (the depth-gap-aware hole fill uses init_kernel_size and init_sigma_* too)
    # init_fill="domain": spatial sigma (px), colour sigma (summed over RGB in [0,1]) and row+column pass pairs, the
    # best `full` RMSE on the 11 Middlebury 2006 scenes (paper + sensor tracks) among the settings that keep the
    # do-no-harm tests (σ_r = 0.2 with 2 pass pairs fit 0.4 % better on sensor but changed a clean float64 map)
    init_dt_sigma_space: float = 6.0
    init_dt_sigma_color: float = 0.2
    init_dt_iterations: int = 1
    # guided upsampling: x⁰ by joint bilateral upsampling ("jbu") or "bicubic"; the TV weight λ is divided by
    # the factor s (TV of an s-times finer grid grows like s for the same surface; the quadratic terms do not)
    upsample_init: str = "jbu"
    # guided upsampling: the degradation K that made the low-resolution input: "area" (averaging, as in the noisy
    # Middlebury sets) or "bicubic" (antialiased bicubic resize, the protocol of the deep guided-SR networks)
    degradation: str = "area"
    # the JBU x⁰ may leave bicubic interpolation by at most this many noise σ plus upsample_init_edge_band times
    # the local depth-edge evidence (upsampling.plane_residual); both 0 = unbounded JBU
    upsample_init_band: float = 3.0
    upsample_init_edge_band: float = 0.5
    # ... except where the JBU x⁰, degraded by K, is further from the input than bicubic interpolation is by more
    # than this many noise σ (a colour edge that moved a depth edge where the data do not put it); 0 = no check
    upsample_init_consistency: float = 2.0
    # do no harm on upsampling: the output is held within upsample_output_band · n plus upsample_output_edge ·
    # max(E − upsample_output_edge_threshold · σ̂, 0) of x⁰ rebuilt with the noise n (E: the depth-edge evidence of
    # upsample_init_*, σ̂ the model's noise estimate, n the white-noise level of noise.white_noise_sigma, 0 on clean
    # resampled maps, whose fine texture the second differences take for noise). Fitted on the eleven Middlebury
    # 2006 images of the guided-SR set (clean ×4: mean 1.682 -> 1.639 and Cloth1 0.823 -> 0.732 < bicubic 0.749 at
    # threshold 8; σ = 5 unchanged). Threshold 16, the smallest tried that keeps every one of them at or below
    # bicubic at ×4, ×8 and ×16 (8 / 12 left Cloth1 ×16 at +1.5 / +0.2 %), costs +0.1 / +0.7 / +1.2 % of the clean
    # mean at ×4 / ×8 / ×16 (README, model choices). 0 = off
    upsample_output_band: float = 3.0
    upsample_output_edge: float = 1.0
    upsample_output_edge_threshold: float = 16.0
    # first_order: each JBU tap extrapolated along its limited slope (no colour texture on slanted surfaces)
    upsample_jbu: dict = field(default_factory=lambda: {"radius": 2, "sigma_space": 1.0, "sigma_color": 0.1,
                                                        "first_order": True})
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
    # 15×15 window, 40 matches (issue 11; were 21×21 and 10): more matched centres make the value prior's plane fit
    # x̄ less noisy, and the nearer window keeps them on the pixel's own surface. Fitted on the 2006 scenes only. Four
    # (Baby1 Cloth2 Midd1 Wood2), `paper` RMSE / MAE, window 21: k 10 / 20 / 30 / 40 / 60 0.872 / 0.819 / 0.806 /
    # 0.801 / 0.797 and 0.620 / 0.578 / 0.563 / 0.557 / 0.549; k 40 with η₃ = 30 in every layer, window 31 / 21 / 15:
    # 0.863 (η₃ 10) / 0.790 / 0.765, MAE 0.609 / 0.530 / 0.511 (window 11, k 30: 0.788 / 0.527); the defaults (η₃ 30
    # on clean samples only, nl_value_weight_clean) 0.764 / 0.509, `sensor` RMSE 1.992 -> 1.994. All eleven 2006
    # scenes, `paper`: 0.863 / 0.615 -> 0.769 / 0.513, better on each. The block-matching stage uses at most the
    # candidates every pixel has (a small image, or the "fast" preset's 11×11 window: 35 at a corner).
    search_window: int = 15
    k: int = 40
    # ... and under guided upsampling, where the value prior is off and the extra matches only cost: the former
    # 21×21 and 10 (2006 scenes area-downsampled with σ = 5, MAE ×2 / ×4: 0.901 / 1.364 against 0.903 / 1.379 with
    # k 40 in 15×15, `python -m torch_depth_sr.evaluation.tune_upsampling`; three times faster)
    upsample_search_window: int = 21
    upsample_k: int = 10
    color_weight: float = 400.0  # ρ: colour distance weight (colour in [0,1])
    temperature: float = 0.5  # h: weight temperature
    include_self: bool = False
    match_layers: tuple = (2, 5)  # layers that redo block matching on the current x (it always runs once on x⁰)
    # how those layers match: "exact" searches the whole window again; "refine" re-ranks the previous matches
    # and the offsets of a step-`rematch_lattice` lattice exactly (block_matching.refine_matches; ~2× cheaper,
    # RMSE +0.3 % paper, +1.0 % sensor on four 2006 scenes; README "Speed")
    rematch: str = "refine"
    rematch_lattice: int = 2
    # nonlocal value prior (beyond the paper, which uses the matches for gradients only): η₃/2‖x − x̄‖² where x̄ is
    # the weighted mean of the matched centres' values, on pixels whose matched values agree (weighted variance
    # below nl_value_var σ̂²); 0 = off (issue 11)
    nl_value_weight: float = 10.0
    nl_value_var: float = 0.25
    # ... and whose weighted centroid lies within this many pixels (how far the fitted plane may be extrapolated)
    nl_value_offset: float = 6.0
    # x̄ is the value at the pixel of a plane fitted to the matched centres (ridge on its slope, px²; 0 = their
    # weighted mean, biased on slopes wherever the centres lie on one side, which needed a 2.5 px centroid gate)
    nl_value_ridge: float = 1.0
    # the centres also weighed by exp(−(x_j − x_i)²/2r²), r in noise σ: an edge-stopping range kernel (0 = off)
    nl_value_range: float = 3.0
    # ... r on samples whose singular gate finds no outliers, from the layer after the first test (0 = as above)
    nl_value_range_clean: float = 1.0
    # ... η₃ on those samples (0 = nl_value_weight): with k = 40 matches x̄ is reliable enough to weigh 30 there
    # (four 2006 scenes, `paper` with k 40 at window 21, η₃ 5 / 10 / 20 / 30 / 40 in every layer: RMSE 0.856 / 0.801 /
    # 0.783 / 0.790 / 0.804, MAE 0.610 / 0.557 / 0.532 / 0.530 / 0.534; 50 on clean samples: 0.773 / 0.508 against
    # 30's 0.764 / 0.509); on samples with outliers 30 costs edges (`sensor` RMSE 1.994 -> 2.110)
    nl_value_weight_clean: float = 30.0
    # singular pixel detection
    singular_tau: float = 0.5
    singular_sigma_floor: float = 2.5
    singular_rounds: int = 3
    # a measured pixel with at least this many measured 8-neighbours within singular_support_tol noise σ of its
    # value lies on a surface, not in the air: it stays trusted whatever its matched blocks say (0 = off; the
    # paper's test). Edges of clean maps match no block well and failed the test (issue 12).
    singular_support: int = 3
    singular_support_tol: float = 2.0
    # ... and so does a pixel on a chain of three agreeing pixels whose value lies beyond its disagreeing
    # neighbours' (a one-pixel gap or wire; a flying pixel lies between the sides of its edge)
    singular_line_support: bool = True
    singular_gate: float = 0.002  # a sample whose share of gross failures is below this keeps Q = measured (0 = off)
    # do no harm: trusted measured pixels end within c·σ_excess of their measurement, σ_excess the noise beyond
    # quantisation (0 on a clean map), c = fidelity_band (0 = off); see fidelity.py
    fidelity_band: float = 4.0
    # edge snapping after the layers (edge_snap.py), only on samples in which the singular test's gate found outliers:
    # snap_rounds passes of "x ← colour-weighted median of its (2 snap_radius + 1)² window where the weight on the
    # median's side of x exceeds snap_share" (colour weights exp(−‖Δc‖₁ / snap_sigma_color), times a Gaussian of
    # σ = snap_sigma_space pixels unless 0). 0 rounds = off. Flying pixels and edge blends go to their side.
    snap_rounds: int = 1
    snap_radius: int = 2
    snap_share: float = 0.6
    snap_sigma_color: float = 0.235
    snap_sigma_space: float = 0.0
    # then, where the 5×5 range of x exceeds snap_refit_edge noise σ (a depth edge is near): x ← the colour-weighted
    # median of the measurements within snap_refit_band noise σ of x in a (2 snap_refit_radius + 1)² window (the
    # layers pull edge values towards the other surface; the side's own measurements are not pulled). 0 = off.
    snap_refit_radius: int = 5
    snap_refit_band: float = 1.5
    snap_refit_edge: float = 2.0
    # linear solves: cg_fixed_iters[i] CG iterations in layer i (the last entry repeats for later layers), with no
    # convergence test, so the host never waits for the device; a sample reaching cg_tol earlier stops changing.
    # () = iterate until every sample reaches cg_tol (at most cg_max_iter; one host synchronisation per iteration).
    # cg_tol = 1e-3 needed up to (7, 5, 5, 4, 3, 3, 2, 2) on the fitting scenes; this default (23 iterations instead of
    # 31) moved their mean RMSE by <= 0.15 % (paper 1.0546 -> 1.0542, sensor 2.0618 -> 2.0648; issue 13)
    cg_fixed_iters: tuple = (5, 4, 3, 3, 3, 2, 2, 1)
    cg_tol: float = 1e-3
    cg_max_iter: int = 50  # also the limit of the implicit backward's solve
    precondition: bool = True
    implicit_backward: bool = False
    extra: dict = field(default_factory=dict)

    def __post_init__(self):
        """Refuse any field outside its domain, naming the field, the value and what is allowed."""
        if isinstance(self.match_layers, list):  # JSON has no tuples
            self.match_layers = tuple(self.match_layers)
        if isinstance(self.cg_fixed_iters, list):
            self.cg_fixed_iters = tuple(self.cg_fixed_iters)
        for f in dataclasses.fields(self):
            _FIELD_CHECKS.get(f.name, _unchecked)(f.name, getattr(self, f.name))
        _check_cross_fields(self)

    def replace(self, **changes) -> "RestorerConfig":
        return dataclasses.replace(self, **changes)

    def with_groups(self, *groups: "_Group") -> "RestorerConfig":
        """A copy with the fields of each group replaced (and checked).

        Examples:
            >>> c = RestorerConfig()
            >>> c.with_groups(dataclasses.replace(c.singular, rounds=1)).singular_rounds
            1
        """
        changes: dict = {}
        for g in groups:
            if not isinstance(g, _Group):
                raise ParameterError("a settings group", g, "a group such as config.singular or config.solver")
            changes.update(g.to_flat())
        return self.replace(**changes)

    # ---- typed groups, one per part of the model (built from the flat fields on each access) ----------
    @property
    def layer(self) -> "LayerConfig":
        """The unrolled layer's terms and initial weights (:class:`~torch_depth_sr.layers.UnrolledLayer`)."""
        return LayerConfig.from_config(self)

    @property
    def block_matching(self) -> "BlockMatchingConfig":
        """Block matching: search, schedule of re-matching and the initial ρ and h."""
        return BlockMatchingConfig.from_config(self)

    @property
    def value_prior(self) -> "ValuePriorConfig":
        """The nonlocal value prior (``nl_value_*``)."""
        return ValuePriorConfig.from_config(self)

    @property
    def singular(self) -> "SingularConfig":
        """The singular-pixel test and its gate (``singular_*``)."""
        return SingularConfig.from_config(self)

    @property
    def solver(self) -> "SolverConfig":
        """The linear solves (``cg_*``, ``precondition``, ``implicit_backward``)."""
        return SolverConfig.from_config(self)

    @property
    def initial(self) -> "InitConfig":
        """The initial estimate x⁰ (``init_*`` and the sided hole fill of ``extra``)."""
        return InitConfig.from_config(self)

    @property
    def edge_snap(self) -> "EdgeSnapConfig":
        """Edge snapping of the output on samples with outliers (``snap_*``)."""
        return EdgeSnapConfig.from_config(self)

    @property
    def upsampling(self) -> "UpsamplingConfig":
        """Guided upsampling: the degradation, x⁰ on the fine grid and the weights' multipliers (``upsample_*``)."""
        return UpsamplingConfig.from_config(self)

    @property
    def refiner(self) -> "RefinerSettings":
        """The learned edge refiner after the model (``refine_*``)."""
        return RefinerSettings.from_config(self)

    def to_json(self) -> str:
        return json.dumps(dataclasses.asdict(self), indent=2, sort_keys=True)

    @classmethod
    def from_dict(cls, d: dict) -> "RestorerConfig":
        """Build from a dict such as ``json.loads(config.to_json())``; every value is checked (ParameterError)."""
        if not isinstance(d, dict):
            raise ParameterError("a RestorerConfig", d, "a dict (a JSON object) of field names to values")
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise ParameterError("keys", sorted(unknown), f"RestorerConfig fields ({', '.join(sorted(known))})",
                                 "Remove or rename the unknown keys.")
        return cls(**d)


# ---- typed groups ----------------------------------------------------------------------------------
class _Group:
    """A frozen group of settings read from the flat :class:`RestorerConfig` fields named in ``_FLAT``
    (group field → flat field)."""

    _FLAT: ClassVar[dict] = {}

    @classmethod
    def from_config(cls, c: RestorerConfig):
        return cls(**{g: getattr(c, f) for g, f in cls._FLAT.items()})

    def to_flat(self) -> dict:
        """The flat fields this group stands for: ``config.replace(**group.to_flat())`` puts it back."""
        return {f: getattr(self, g) for g, f in self._FLAT.items()}


def _same(*names: str) -> dict:
    return {n: n for n in names}


def _prefixed(prefix: str, *names: str) -> dict:
    return {n: prefix + n for n in names}


@dataclass(frozen=True)
class LayerConfig(_Group):
    """What one unrolled layer computes: initial λ, η, γ, μ₁, μ₂, the shrinkage, the terms switched on, the
    guided prior β (on untrusted pixels; on singular ones too with ``prior_on_singular``) and whether a guidance
    network (:class:`~torch_depth_sr.guidance.GuidanceNet`, ``guidance_channels`` wide, multipliers in
    [1/``guidance_range``, ``guidance_range``]) makes the thresholds per-pixel maps."""

    lam: float
    eta: float
    eta_clean: float
    gamma: float
    mu1: float
    mu2: float
    isotropic: bool
    use_nonlocal: bool
    use_outliers: bool
    use_singular: bool
    guided_prior: float
    prior_on_singular: bool
    guidance_net: bool
    guidance_channels: int
    guidance_range: float
    _FLAT: ClassVar[dict] = _same("lam", "eta", "eta_clean", "gamma", "mu1", "mu2", "isotropic", "use_nonlocal",
                                  "use_outliers", "use_singular", "guided_prior", "prior_on_singular",
                                  "guidance_net", "guidance_channels", "guidance_range")


@dataclass(frozen=True)
class BlockMatchingConfig(_Group):
    """Block matching (:func:`~torch_depth_sr.block_matching.block_match`), the layers that match again and how,
    and the initial colour weight ρ and temperature h of the model."""

    block_size: int
    search_window: int
    k: int
    include_self: bool
    match_layers: tuple
    rematch: str
    rematch_lattice: int
    color_weight: float
    temperature: float
    upsample_search_window: int
    upsample_k: int
    _FLAT: ClassVar[dict] = _same("block_size", "search_window", "k", "include_self", "match_layers", "rematch",
                                  "rematch_lattice", "color_weight", "temperature", "upsample_search_window",
                                  "upsample_k")

    def window_and_k(self, upsampling: bool) -> tuple[int, int]:
        """``(search_window, k)`` for restoration on the observation grid, or for guided upsampling."""
        return (self.upsample_search_window, self.upsample_k) if upsampling else (self.search_window, self.k)


@dataclass(frozen=True)
class ValuePriorConfig(_Group):
    """The nonlocal value prior η₃/2‖x − x̄‖² (:func:`~torch_depth_sr.nonlocal_prior.nonlocal_terms`); flat fields
    ``nl_value_weight``, ``nl_value_var``, ``nl_value_offset``, ``nl_value_ridge``, ``nl_value_range``,
    ``nl_value_range_clean``, ``nl_value_weight_clean``."""

    weight: float
    var: float
    offset: float
    ridge: float
    range: float
    range_clean: float
    weight_clean: float
    _FLAT: ClassVar[dict] = _prefixed("nl_value_", "weight", "var", "offset", "ridge", "range", "range_clean",
                                      "weight_clean")


@dataclass(frozen=True)
class SingularConfig(_Group):
    """The singular-pixel test (:func:`~torch_depth_sr.singular.detect_singular`), the neighbour and line support
    that keeps surface pixels trusted, and the per-sample gate; flat fields ``singular_*``."""

    tau: float
    sigma_floor: float
    rounds: int
    support: int
    support_tol: float
    line_support: bool
    gate: float
    _FLAT: ClassVar[dict] = _prefixed("singular_", "tau", "sigma_floor", "rounds", "support", "support_tol",
                                      "line_support", "gate")


@dataclass(frozen=True)
class EdgeSnapConfig(_Group):
    """Edge snapping of the output (:func:`~torch_depth_sr.edge_snap.snap_to_sides`, ``rounds`` passes) and the refit
    of values near depth edges to the measurements (:func:`~torch_depth_sr.edge_snap.refit_to_measurements`,
    ``refit_radius`` 0 = off), on the samples in which the singular test's gate found outliers; flat fields
    ``snap_*``."""

    rounds: int
    radius: int
    share: float
    sigma_color: float
    sigma_space: float
    refit_radius: int
    refit_band: float
    refit_edge: float
    _FLAT: ClassVar[dict] = _prefixed("snap_", "rounds", "radius", "share", "sigma_color", "sigma_space",
                                      "refit_radius", "refit_band", "refit_edge")

    def arguments(self) -> dict:
        """Keyword arguments of :func:`~torch_depth_sr.edge_snap.snap_to_sides` (``sigma_space`` 0 = flat window)."""
        return dict(rounds=self.rounds, radius=self.radius, share=self.share, sigma_color=self.sigma_color,
                    sigma_space=self.sigma_space or None)

    def refit_arguments(self) -> dict:
        """Keyword arguments of :func:`~torch_depth_sr.edge_snap.refit_to_measurements`."""
        return dict(radius=self.refit_radius, band=self.refit_band, edge=self.refit_edge, sigma_color=self.sigma_color)


@dataclass(frozen=True)
class RefinerSettings(_Group):
    """The learned edge refiner after the model (:class:`~torch_depth_sr.refiner.EdgeRefiner`): on or off (``net``),
    ``channels`` wide with ``layers`` hidden convolutions, for one ``task``: ``"upsample"`` (runs when K ≠ I) or
    ``"denoise"`` (runs when K = I); flat fields ``refine_*``."""

    net: bool
    channels: int
    layers: int
    task: str
    _FLAT: ClassVar[dict] = _prefixed("refine_", "net", "channels", "layers", "task")

    def runs_for(self, upsampling: bool) -> bool:
        """Whether the refiner corrects an output of this task (upsampling or not)."""
        return self.net and (self.task == "upsample") == upsampling


@dataclass(frozen=True)
class SolverConfig(_Group):
    """The x-update's preconditioned CG (:func:`~torch_depth_sr.solvers.implicit.cg_solve`); flat fields
    ``cg_fixed_iters``, ``cg_tol``, ``cg_max_iter``, ``precondition``, ``implicit_backward``."""

    fixed_iters: tuple
    tol: float
    max_iter: int
    precondition: bool
    implicit_backward: bool
    _FLAT: ClassVar[dict] = {"fixed_iters": "cg_fixed_iters", "tol": "cg_tol", "max_iter": "cg_max_iter",
                             **_same("precondition", "implicit_backward")}

    def iterations(self, index: int) -> Optional[int]:
        """The fixed CG iteration count of layer ``index`` (the schedule's last entry repeats); None = to ``tol``."""
        if not self.fixed_iters:
            return None
        return int(self.fixed_iters[min(index, len(self.fixed_iters) - 1)])


# Depth-gap-aware hole fill of x⁰ (torch_depth_sr.fill.fill_holes_sided), switched and tuned through
# ``config.extra``: ``{"sided_fill": False}`` restores the plain masked-JBF / push-pull fill of the holes;
# ``{"sided_fill_params": {...}}`` overrides the arguments below (gap in noise-σ units of the normalised depth).
SIDED_FILL_DEFAULTS = dict(gap=4.0, min_share=0.75, passes=8, choice_sigma_space=1.5, ambiguous="mix")


@dataclass(frozen=True)
class SidedFillConfig:
    """Arguments of :func:`~torch_depth_sr.fill.fill_holes_sided` for x⁰ (``config.extra["sided_fill_params"]``
    overrides :data:`SIDED_FILL_DEFAULTS`); ``ambiguous="mix"``: a hole whose side is not clear keeps the
    weighted mean of both sides. ``quantiles`` is passed only when given."""

    gap: float = SIDED_FILL_DEFAULTS["gap"]
    min_share: float = SIDED_FILL_DEFAULTS["min_share"]
    passes: int = SIDED_FILL_DEFAULTS["passes"]
    choice_sigma_space: Optional[float] = SIDED_FILL_DEFAULTS["choice_sigma_space"]
    ambiguous: str = SIDED_FILL_DEFAULTS["ambiguous"]
    quantiles: Optional[tuple] = None

    def fill_arguments(self) -> dict:
        """Keyword arguments for ``fill_holes_sided`` (all but ``ambiguous``)."""
        kw = dict(gap=self.gap, min_share=self.min_share, passes=self.passes,
                  choice_sigma_space=self.choice_sigma_space)
        if self.quantiles is not None:
            kw["quantiles"] = self.quantiles
        return kw


@dataclass(frozen=True)
class InitConfig(_Group):
    """The initial estimate x⁰ (:func:`~torch_depth_sr.model.initial_estimate`): the colour-guided filter and its
    settings, whether measured values are kept, whether Q⁰ comes from a singular test, and the sided hole fill
    (``None`` = off; ``config.extra["sided_fill"]`` and ``["sided_fill_params"]``). Flat fields ``init_*``."""

    fill: str
    keep_observed: bool
    singular: bool
    kernel_size: int
    sigma_space: float
    sigma_color: float
    dt_sigma_space: float
    dt_sigma_color: float
    dt_iterations: int
    sided_fill: Optional[SidedFillConfig]
    _FLAT: ClassVar[dict] = _prefixed("init_", "fill", "keep_observed", "singular", "kernel_size", "sigma_space",
                                      "sigma_color", "dt_sigma_space", "dt_sigma_color", "dt_iterations")

    @classmethod
    def from_config(cls, c: RestorerConfig) -> "InitConfig":
        sided = None
        if bool(c.extra.get("sided_fill", True)) and c.init_fill != "pushpull":
            params = c.extra.get("sided_fill_params", {})
            allowed = [f.name for f in dataclasses.fields(SidedFillConfig)]
            if not isinstance(params, dict) or set(params) - set(allowed):
                raise ParameterError('extra["sided_fill_params"]', params, f"a dict with some of {allowed}")
            sided = SidedFillConfig(**params)
        return cls(**{g: getattr(c, f) for g, f in cls._FLAT.items()}, sided_fill=sided)


@dataclass(frozen=True)
class JBUConfig:
    """Joint bilateral upsampling of x⁰ (:func:`~torch_depth_sr.guided_filters.joint_bilateral_upsample`;
    the defaults are that function's)."""

    radius: int = 2
    sigma_space: float = 1.0
    sigma_color: float = 0.1
    first_order: bool = True


@dataclass(frozen=True)
class LayerMultipliers:
    """Multipliers on the layer weights under guided upsampling (1 = unchanged)."""

    lam: float = 1.0
    eta: float = 1.0
    gamma: float = 1.0
    mu1: float = 1.0
    mu2: float = 1.0


@dataclass(frozen=True)
class UpsamplingConfig(_Group):
    """Guided upsampling: the degradation ``K`` (``"area"`` or ``"bicubic"``, built by
    :func:`~torch_depth_sr.operators.degradation_operator`), x⁰ on the fine grid (``init``: ``"jbu"`` held within
    ``init_band`` noise σ plus ``init_edge_band`` times the depth-edge evidence of bicubic interpolation, or
    ``"bicubic"``; :func:`~torch_depth_sr.upsampling.upsample_initial`) and the layer weights' policy
    (:meth:`layer_weights`). Flat fields ``degradation`` and ``upsample_*``."""

    degradation: str
    init: str
    init_band: float
    init_edge_band: float
    init_consistency: float
    output_band: float
    output_edge: float
    output_edge_threshold: float
    jbu: JBUConfig
    tv_per_factor: bool
    multipliers: LayerMultipliers
    _FLAT: ClassVar[dict] = {"degradation": "degradation", "init": "upsample_init", "init_band": "upsample_init_band",
                             "init_edge_band": "upsample_init_edge_band",
                             "init_consistency": "upsample_init_consistency", "jbu": "upsample_jbu",
                             "output_band": "upsample_output_band", "output_edge": "upsample_output_edge",
                             "output_edge_threshold": "upsample_output_edge_threshold",
                             "tv_per_factor": "upsample_tv_per_factor",
                             "multipliers": "upsample_scale"}

    @classmethod
    def from_config(cls, c: RestorerConfig) -> "UpsamplingConfig":
        return cls(degradation=c.degradation, init=c.upsample_init, init_band=c.upsample_init_band,
                   init_edge_band=c.upsample_init_edge_band, init_consistency=c.upsample_init_consistency,
                   output_band=c.upsample_output_band, output_edge=c.upsample_output_edge,
                   output_edge_threshold=c.upsample_output_edge_threshold,
                   jbu=JBUConfig(**c.upsample_jbu),
                   tv_per_factor=c.upsample_tv_per_factor,
                   multipliers=LayerMultipliers(**c.upsample_scale))

    def to_flat(self) -> dict:
        d = super().to_flat()
        d["upsample_jbu"] = dataclasses.asdict(self.jbu)
        d["upsample_scale"] = dataclasses.asdict(self.multipliers)
        return d

    def layer_weights(self, degradation: Degradation, lam: torch.Tensor, eta: torch.Tensor, gamma: torch.Tensor,
                      mu1: torch.Tensor, mu2: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """The layer's (λ, η, γ, μ₁, μ₂) for the degradation ``K``: unchanged when ``K = I``; under guided
        upsampling each times its multiplier, and λ divided by ``s = K.scale`` with ``tv_per_factor`` (TV of an
        s-times finer grid grows like s for the same surface; the quadratic terms do not)."""
        weights = (lam, eta, gamma, mu1, mu2)
        if degradation.is_identity:
            return weights
        m = self.multipliers
        lam, eta, gamma, mu1, mu2 = (v * float(f) for v, f in zip(weights, (m.lam, m.eta, m.gamma, m.mu1, m.mu2)))
        if self.tv_per_factor:
            lam = lam / degradation.scale
        return lam, eta, gamma, mu1, mu2


def load_config_file(path: str | Path) -> RestorerConfig:
    """Read a ``config.json`` written by :meth:`RestorerConfig.to_json` (or by hand).

    Raises:
        ModelFileError: the file is missing or unreadable, is not a JSON object (the message gives the line
            and column of invalid JSON), or holds a field out of its domain (the message names the field).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ModelFileError(path, "file not found; a saved model folder holds config.json and state_dict.pt "
                                   "(DepthRestorer.save writes both).") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelFileError(path, f"cannot be read as UTF-8 text ({exc}).") from exc
    try:
        d = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ModelFileError(path, f"invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}.") from exc
    if not isinstance(d, dict):
        raise ModelFileError(path, "must hold a JSON object of RestorerConfig fields, e.g. {\"num_layers\": 8}; "
                                   f"got a JSON {_json_kind(d)}.")
    try:
        return RestorerConfig.from_dict(d)
    except ParameterError as exc:
        raise ModelFileError(path, f"invalid field: {exc}") from exc


def _json_kind(v: Any) -> str:
    if v is None:
        return "null"
    return {bool: "boolean", int: "number", float: "number", str: "string", list: "array"}.get(type(v), "value")


ABLATIONS = {
    # without the singular detector every measurement would count as trusted, flying pixels included, so the
    # fidelity band (an extension that relies on the detector) is off in these two ablations
    "tv": dict(use_nonlocal=False, use_outliers=False, use_singular=False, fidelity_band=0.0, nl_value_weight=0.0),
    "tv+nl": dict(use_nonlocal=True, use_outliers=False, use_singular=False, fidelity_band=0.0, nl_value_weight=0.0),
    "full": dict(use_nonlocal=True, use_outliers=True, use_singular=True),
    # the paper's model as it stands (model.md): 5×5 blocks, 21×21 window, k = 10, exact re-matching, x⁰ = y with its holes pulled-pushed,
    # none of the library's extensions (the guided prior on untrusted pixels, the neighbour/line support and the
    # gate of the singular test, the fidelity band, the nonlocal value prior). Weights stay in noise-σ units.
    "paper": dict(use_nonlocal=True, use_outliers=True, use_singular=True, block_size=5, search_window=21, k=10,
                  rematch="exact",
                  init_fill="pushpull", guided_prior=0.0, singular_support=0, singular_line_support=False,
                  singular_gate=0.0, fidelity_band=0.0, nl_value_weight=0.0),
}

# Speed presets: settings that trade a measured amount of accuracy for time (README, "Speed and memory").
# "fast": the defaults before issue 11's k = 40 (10 matches, the value prior's weight 10 on every sample) with an
# 11×11 search window and one re-match (layer 2) instead of 21×21 and two; measured against those former defaults on
# the full 2006 scenes: RMSE +0.7 % (paper) and +0.9 % (sensor), about half the time at 640×480. The defaults since
# (k 40 in 15×15, README model choices) are about 2.6× slower than those former defaults.
PRESETS = {
    "fast": dict(search_window=11, k=10, nl_value_weight_clean=0.0, upsample_search_window=11, match_layers=(2,)),
}


# ---- field domains -------------------------------------------------------------------------------
def _is_int(v: Any) -> bool:
    return isinstance(v, Integral) and not isinstance(v, bool)


def _is_real(v: Any) -> bool:
    return isinstance(v, Real) and not isinstance(v, bool)


def _int(lo: int, odd: bool = False) -> Callable[[str, Any], None]:
    allowed = f"an {'odd ' if odd else ''}int >= {lo}"

    def check(name: str, v: Any) -> None:
        if not _is_int(v) or v < lo or (odd and v % 2 == 0):
            hint = "The block is centred on the pixel, so its size is odd." if odd and _is_int(v) and v >= lo else ""
            raise ParameterError(name, v, allowed, hint)
    return check


def _real(lo: float, hi: float = math.inf, lo_open: bool = True, hi_open: bool = False) -> Callable[[str, Any], None]:
    left, right = "(" if lo_open else "[", ")" if hi_open or hi == math.inf else "]"
    allowed = f"a finite number in {left}{lo:g}, {hi:g}{right}"
    if hi == math.inf:
        allowed = f"a finite number {'>' if lo_open else '>='} {lo:g}"

    def check(name: str, v: Any) -> None:
        ok = _is_real(v) and math.isfinite(v)
        ok = ok and (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
        if not ok:
            raise ParameterError(name, v, allowed)
    return check


def _bool(name: str, v: Any) -> None:
    if not isinstance(v, bool):
        raise ParameterError(name, v, "True or False")


def _choice(*options: str) -> Callable[[str, Any], None]:
    def check(name: str, v: Any) -> None:
        if not isinstance(v, str) or v not in options:
            raise ParameterError(name, v, f"one of {list(options)}")
    return check


def _match_layers(name: str, v: Any) -> None:
    # indices beyond num_layers are allowed: they never fire (the default (2, 5) serves 2-layer models too)
    if not isinstance(v, tuple) or not all(_is_int(i) and i >= 0 for i in v):
        raise ParameterError(name, v, "a tuple or list of layer indices (ints >= 0), e.g. (2, 5) or ()")


def _cg_fixed_iters(name: str, v: Any) -> None:
    if not isinstance(v, tuple) or not all(_is_int(i) and i >= 1 for i in v):
        raise ParameterError(name, v, "a tuple or list of CG iteration counts per layer (ints >= 1), e.g. (5, 3, 1), "
                             "or () for a convergence test on cg_tol")


def _upsample_jbu(name: str, v: Any) -> None:
    allowed = ("a dict with some of 'radius' (int >= 0), 'sigma_space' and 'sigma_color' (finite numbers > 0) and "
               "'first_order' (bool)")
    if not isinstance(v, dict) or set(v) - {"radius", "sigma_space", "sigma_color", "first_order"}:
        raise ParameterError(name, v, allowed)
    if "first_order" in v and not isinstance(v["first_order"], bool):
        raise ParameterError(name, v, allowed)
    if "radius" in v and not (_is_int(v["radius"]) and v["radius"] >= 0):
        raise ParameterError(name, v, allowed)
    for key in ("sigma_space", "sigma_color"):
        if key in v and not (_is_real(v[key]) and math.isfinite(v[key]) and v[key] > 0):
            raise ParameterError(name, v, allowed)


def _upsample_scale(name: str, v: Any) -> None:
    names = ["eta", "gamma", "lam", "mu1", "mu2"]
    ok = isinstance(v, dict) and not set(v) - set(names)
    ok = ok and all(_is_real(m) and math.isfinite(m) and m > 0 for m in v.values())
    if not ok:
        raise ParameterError(name, v, f"a dict mapping layer parameters {names} to positive multipliers")


def _unchecked(name: str, v: Any) -> None:
    """A field without a domain yet (tests/test_input_safety.py requires one for every field)."""


def _dict(name: str, v: Any) -> None:
    if not isinstance(v, dict):
        raise ParameterError(name, v, "a dict")


_positive = _real(0.0)
_FIELD_CHECKS: dict[str, Callable[[str, Any], None]] = {
    "num_layers": _int(1),
    # the layer parameters are softplus-positive (0 would be a raw value of −inf)
    "lam": _positive, "eta": _positive, "eta_clean": _positive, "gamma": _positive, "mu1": _positive, "mu2": _positive,
    "isotropic": _bool,
    "init_fill": _choice("domain", "jbf", "pushpull"),
    "guided_prior": _real(0.0, lo_open=False),
    "prior_on_singular": _bool, "init_singular": _bool, "guidance_net": _bool, "guidance_channels": _int(1), "init_keep_observed": _bool,
    "guidance_range": _real(1.0, lo_open=False),
    "refine_net": _bool, "refine_channels": _int(1), "refine_layers": _int(0),
    "refine_task": _choice("upsample", "denoise"),
    "init_kernel_size": _int(1),
    "init_sigma_space": _positive, "init_sigma_color": _positive,
    "init_dt_sigma_space": _positive, "init_dt_sigma_color": _positive, "init_dt_iterations": _int(1),
    "upsample_init": _choice("jbu", "bicubic"),
    "degradation": _choice("area", "bicubic"),
    "nl_value_weight": _real(0.0, lo_open=False),
    "nl_value_var": _real(0.0),
    "nl_value_offset": _real(0.0),
    "nl_value_ridge": _real(0.0, lo_open=False),
    "nl_value_range": _real(0.0, lo_open=False),
    "nl_value_range_clean": _real(0.0, lo_open=False),
    "nl_value_weight_clean": _real(0.0, lo_open=False),
    "upsample_init_band": _real(0.0, lo_open=False),
    "upsample_init_edge_band": _real(0.0, lo_open=False),
    "upsample_init_consistency": _real(0.0, lo_open=False),
    "upsample_output_band": _real(0.0, lo_open=False),
    "upsample_output_edge": _real(0.0, lo_open=False),
    "upsample_output_edge_threshold": _real(0.0, lo_open=False),
    "upsample_jbu": _upsample_jbu,
    "upsample_tv_per_factor": _bool,
    "upsample_scale": _upsample_scale,
    "use_nonlocal": _bool, "use_outliers": _bool, "use_singular": _bool,
    "block_size": _int(1, odd=True),
    "search_window": _int(1, odd=True),
    "k": _int(1),
    "upsample_search_window": _int(1, odd=True),
    "upsample_k": _int(1),
    "color_weight": _real(0.0, lo_open=False),
    "temperature": _positive,
    "include_self": _bool,
    "match_layers": _match_layers,
    "rematch": _choice("exact", "refine"),
    "rematch_lattice": _int(0),
    "singular_tau": _real(0.0, 1.0),
    "singular_sigma_floor": _positive,
    "singular_rounds": _int(1),
    "singular_support": _int(0),
    "singular_support_tol": _positive,
    "singular_line_support": _bool,
    "singular_gate": _real(0.0, 1.0, lo_open=False),
    "fidelity_band": _real(0.0, lo_open=False),
    "snap_rounds": _int(0),
    "snap_radius": _int(1),
    "snap_share": _real(0.5, 1.0, lo_open=False, hi_open=True),
    "snap_sigma_color": _real(0.0),
    "snap_sigma_space": _real(0.0, lo_open=False),
    "snap_refit_radius": _int(0),
    "snap_refit_band": _real(0.0),
    "snap_refit_edge": _real(0.0, lo_open=False),
    "cg_fixed_iters": _cg_fixed_iters,
    "cg_tol": _positive,
    "cg_max_iter": _int(1),
    "precondition": _bool, "implicit_backward": _bool,
    "extra": _dict,
}


def _check_cross_fields(c: RestorerConfig) -> None:
    """Constraints between fields (each field is already in its own domain)."""
    for k_name, sw_name in (("k", "search_window"), ("upsample_k", "upsample_search_window")):
        k, sw = getattr(c, k_name), getattr(c, sw_name)
        candidates = sw ** 2 - (0 if c.include_self else 1)
        if k > candidates:
            raise ParameterError(k_name, k, f"<= {candidates}, the number of candidate blocks in a "
                                 f"{sw}x{sw} search window (include_self={c.include_self})",
                                 f"Use a smaller {k_name} or a larger {sw_name}.")
