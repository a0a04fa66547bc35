"""The settings groups of :class:`~torch_depth_sr.config.RestorerConfig`: one frozen dataclass per part of the
model, each checked on construction. An optional group set to ``None`` in the config switches its step off.

Units: depth is normalised by the estimated noise level (``noise.py``), so thresholds, bands and weights are in
noise-σ units; the block-matching temperature is in σ² per block pixel. Why each default is what it is, with the
measurement behind it: ``docs/model-choices/``.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar, Optional

from ..errors import ParameterError
from .domains import boolean, choice, int_tuple, integer, non_negative, optional, positive, real

__all__ = [
    "BlockMatchingConfig", "CleanSamples", "EdgeRefit", "EdgeSnap", "FidelityBand", "Group", "Guidance",
    "GuidedPrior", "InitConfig", "JBUConfig", "LayerMultipliers", "LayerWeights", "OutputHold", "Refiner",
    "SidedFill", "SingularConfig", "SolverConfig", "StreamConfig", "UpsamplingConfig", "ValuePrior",
]


class Group:
    """A frozen settings group: ``_CHECKS`` gives each field's domain, ``_NESTED`` the fields that are groups."""

    _NAME: ClassVar[str] = ""
    _CHECKS: ClassVar[dict] = {}
    _NESTED: ClassVar[dict] = {}

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, list):  # JSON has no tuples
                object.__setattr__(self, f.name, v := tuple(v))
            nested = self._NESTED.get(f.name)
            if nested is not None and isinstance(v, dict):
                object.__setattr__(self, f.name, nested.from_dict(v, f"{self._NAME}.{f.name}"))
            elif nested is not None and not isinstance(v, nested):
                raise ParameterError(f"{self._NAME}.{f.name}", v, f"a {nested.__name__} or a dict of its fields")
            else:
                self._CHECKS.get(f.name, _no_check)(f"{self._NAME}.{f.name}", v)

    @classmethod
    def from_dict(cls, values: Any, name: str = "") -> "Group":
        """The group from a dict of some of its fields (the rest keep their defaults); unknown keys are refused."""
        name = name or cls._NAME
        known = [f.name for f in dataclasses.fields(cls)]
        if not isinstance(values, dict) or set(values) - set(known):
            raise ParameterError(name, values, f"a dict with some of {known}")
        return cls(**values)

    def replace(self, **changes: Any) -> "Group":
        """A copy with ``changes``; a nested group may be given as a dict of changes."""
        for k, v in list(changes.items()):
            if k in self._NESTED and isinstance(v, dict):
                changes[k] = getattr(self, k).replace(**v)
        known = [f.name for f in dataclasses.fields(self)]
        if set(changes) - set(known):
            raise ParameterError(self._NAME, changes, f"changes of some of {known}")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def _no_check(name: str, v: Any) -> None:
    """Fields whose type the dataclass already fixes (none today)."""


@dataclass(frozen=True)
class LayerWeights(Group):
    """Initial values of every layer's λ (TV), η (nonlocal gradient), γ (sparse outliers), μ₁, μ₂ (splitting) —
    softplus-positive parameters when trainable — and isotropic (group) instead of anisotropic TV shrinkage."""

    lam: float = 1.0
    eta: float = 2.0
    gamma: float = 3.0
    mu1: float = 2.0
    mu2: float = 0.5
    isotropic: bool = False
    _NAME: ClassVar[str] = "weights"
    _CHECKS: ClassVar[dict] = {**dict.fromkeys(("lam", "eta", "gamma", "mu1", "mu2"), positive),
                               "isotropic": boolean}


@dataclass(frozen=True)
class BlockMatchingConfig(Group):
    """Block matching (:func:`~torch_depth_sr.block_matching.block_match`): block and window sizes, k matches
    (``upsample_*`` under guided upsampling), the layers that match again (``match_layers``) and how (``"exact"``,
    or ``"refine"``: the previous matches and a step-``rematch_lattice`` lattice of the window re-ranked), and the
    initial colour weight ρ and temperature h."""

    block_size: int = 3
    search_window: int = 15
    k: int = 40
    include_self: bool = False
    match_layers: tuple = (2, 5)
    rematch: str = "refine"
    rematch_lattice: int = 2
    color_weight: float = 400.0
    temperature: float = 0.5
    upsample_search_window: int = 21
    upsample_k: int = 10
    _NAME: ClassVar[str] = "block_matching"
    _CHECKS: ClassVar[dict] = {
        "block_size": integer(1, odd=True), "search_window": integer(1, odd=True), "k": integer(1),
        "include_self": boolean, "match_layers": int_tuple(0, "(2, 5) or ()"),
        "rematch": choice("exact", "refine"), "rematch_lattice": integer(0), "color_weight": non_negative,
        "temperature": positive, "upsample_search_window": integer(1, odd=True), "upsample_k": integer(1)}

    def __post_init__(self) -> None:
        super().__post_init__()
        for k_name, sw_name in (("k", "search_window"), ("upsample_k", "upsample_search_window")):
            k, sw = getattr(self, k_name), getattr(self, sw_name)
            candidates = sw ** 2 - (0 if self.include_self else 1)
            if k > candidates:
                raise ParameterError(f"block_matching.{k_name}", k, f"<= {candidates}, the number of candidate "
                                     f"blocks in a {sw}x{sw} search window (include_self={self.include_self})",
                                     f"Use a smaller {k_name} or a larger {sw_name}.")

    def window_and_k(self) -> dict:
        """``(search_window, k)`` per task."""
        return {"denoise": (self.search_window, self.k), "upsample": (self.upsample_search_window, self.upsample_k)}


@dataclass(frozen=True)
class SingularConfig(Group):
    """The singular-pixel test (:func:`~torch_depth_sr.singular.detect_singular`: ``tau``, ``sigma_floor``,
    ``rounds``); measured pixels with at least ``support`` measured 8-neighbours within ``support_tol`` noise σ
    (0 = no such rule), or on a thin line of agreeing pixels (``line_support``), stay trusted; ``gate``: a sample
    whose share of gross failures is below it keeps Q = measured and counts as clean (None = no gate)."""

    tau: float = 0.5
    sigma_floor: float = 2.5
    rounds: int = 3
    support: int = 3
    support_tol: float = 2.0
    line_support: bool = True
    gate: Optional[float] = 0.002
    _NAME: ClassVar[str] = "singular"
    _CHECKS: ClassVar[dict] = {
        "tau": real(0.0, 1.0), "sigma_floor": positive, "rounds": integer(1), "support": integer(0),
        "support_tol": positive, "line_support": boolean, "gate": optional(real(0.0, 1.0))}


@dataclass(frozen=True)
class SolverConfig(Group):
    """The x-update's preconditioned CG (:func:`~torch_depth_sr.solvers.implicit.cg_solve`): ``fixed_iters[i]``
    iterations in layer i (the last entry repeats; no host synchronisation), or ``()`` = to ``tol`` (at most
    ``max_iter``, also the implicit backward's limit)."""

    fixed_iters: tuple = (5, 4, 3, 3, 3, 2, 2, 1)
    tol: float = 1e-3
    max_iter: int = 50
    precondition: bool = True
    implicit_backward: bool = False
    _NAME: ClassVar[str] = "solver"
    _CHECKS: ClassVar[dict] = {"fixed_iters": int_tuple(1, "(5, 3, 1), or () for a convergence test on tol"),
                               "tol": positive, "max_iter": integer(1), "precondition": boolean,
                               "implicit_backward": boolean}

    def iterations(self, index: int) -> Optional[int]:
        """The fixed CG iteration count of layer ``index`` (the schedule's last entry repeats); None = to ``tol``."""
        if not self.fixed_iters:
            return None
        return int(self.fixed_iters[min(index, len(self.fixed_iters) - 1)])


@dataclass(frozen=True)
class InitConfig(Group):
    """The initial estimate x⁰ on the observation grid (:func:`~torch_depth_sr.initial.initial_estimate`): ``fill``
    ``"domain"`` (masked domain-transform filter, ``dt_*``), ``"jbf"`` (masked joint bilateral filter,
    ``kernel_size``, ``sigma_*``, which the sided hole fill uses too) or ``"pushpull"`` (no colour); whether
    measured values are kept and whether Q⁰ comes from a singular test against the guided estimate."""

    fill: str = "domain"
    keep_observed: bool = True
    singular: bool = False
    kernel_size: int = 11
    sigma_space: float = 6.0
    sigma_color: float = 0.025
    dt_sigma_space: float = 6.0
    dt_sigma_color: float = 0.2
    dt_iterations: int = 1
    _NAME: ClassVar[str] = "initial"
    _CHECKS: ClassVar[dict] = {
        "fill": choice("domain", "jbf", "pushpull"), "keep_observed": boolean, "singular": boolean,
        "kernel_size": integer(1), "sigma_space": positive, "sigma_color": positive,
        "dt_sigma_space": positive, "dt_sigma_color": positive, "dt_iterations": integer(1)}


@dataclass(frozen=True)
class SidedFill(Group):
    """The depth-gap-aware hole fill of x⁰ (:func:`~torch_depth_sr.fill.fill_holes_sided`; ``gap`` in noise σ):
    a hole next to a depth gap takes the values of one side; ``ambiguous="mix"``: a hole whose side is not clear
    keeps the weighted mean of both (``"take"``: the likelier side). ``quantiles`` is passed only when given."""

    gap: float = 4.0
    min_share: float = 0.75
    passes: int = 8
    choice_sigma_space: Optional[float] = 1.5
    ambiguous: str = "mix"
    quantiles: Optional[tuple] = None
    _NAME: ClassVar[str] = "sided_fill"
    _CHECKS: ClassVar[dict] = {"gap": positive, "min_share": real(0.0, 1.0), "passes": integer(1),
                               "choice_sigma_space": optional(positive), "ambiguous": choice("mix", "take")}

    def fill_arguments(self) -> dict:
        """Keyword arguments for ``fill_holes_sided`` (all but ``ambiguous``)."""
        kw = dict(gap=self.gap, min_share=self.min_share, passes=self.passes,
                  choice_sigma_space=self.choice_sigma_space)
        if self.quantiles is not None:
            kw["quantiles"] = self.quantiles
        return kw


@dataclass(frozen=True)
class ValuePrior(Group):
    """The nonlocal value prior η₃/2‖x − x̄‖² (:func:`~torch_depth_sr.nonlocal_prior.nonlocal_terms`), denoising
    only: x̄ the value at the pixel of a plane (ridge ``ridge`` px² on its slope) fitted to the matched centres, on
    pixels whose matched values agree (residual variance below ``var`` σ̂²) and whose centroid lies within
    ``offset`` px; ``range``: the centres also weighed by an edge-stopping range kernel of r noise σ (None = off)."""

    weight: float = 10.0
    var: float = 0.25
    offset: float = 6.0
    ridge: float = 1.0
    range: Optional[float] = 3.0
    _NAME: ClassVar[str] = "value_prior"
    _CHECKS: ClassVar[dict] = {"weight": positive, "var": positive, "offset": positive,
                               "ridge": non_negative, "range": optional(positive)}


@dataclass(frozen=True)
class CleanSamples(Group):
    """Other weights on samples the singular test's gate finds free of outliers, from the layer after the first
    gated test on: η times ``eta``; the value prior's range r = ``value_range`` and weight η₃ = ``value_weight``
    (None: as on other samples)."""

    eta: float = 0.25
    value_range: Optional[float] = 1.0
    value_weight: Optional[float] = 30.0
    _NAME: ClassVar[str] = "clean_samples"
    _CHECKS: ClassVar[dict] = {"eta": positive, "value_range": optional(positive),
                               "value_weight": optional(positive)}


@dataclass(frozen=True)
class GuidedPrior(Group):
    """β: untrusted pixels (missing, and singular ones with ``on_singular``) pulled with weight ``weight`` to the
    colour-guided estimate (denoising)."""

    weight: float = 3.2
    on_singular: bool = True
    _NAME: ClassVar[str] = "guided_prior"
    _CHECKS: ClassVar[dict] = {"weight": positive, "on_singular": boolean}


@dataclass(frozen=True)
class FidelityBand(Group):
    """Do no harm (denoising): trusted measured pixels end within ``width`` · σ_excess of their measurement,
    σ_excess the noise beyond quantisation (:mod:`torch_depth_sr.fidelity`)."""

    width: float = 4.0
    _NAME: ClassVar[str] = "fidelity"
    _CHECKS: ClassVar[dict] = {"width": positive}


@dataclass(frozen=True)
class JBUConfig(Group):
    """Joint bilateral upsampling of x⁰ (:func:`~torch_depth_sr.guided_filters.joint_bilateral_upsample`)."""

    radius: int = 2
    sigma_space: float = 1.0
    sigma_color: float = 0.1
    first_order: bool = True
    _NAME: ClassVar[str] = "upsampling.jbu"
    _CHECKS: ClassVar[dict] = {"radius": integer(0), "sigma_space": positive, "sigma_color": positive,
                               "first_order": boolean}


@dataclass(frozen=True)
class LayerMultipliers(Group):
    """Multipliers on the layer weights under guided upsampling (1 = unchanged)."""

    lam: float = 1.0
    eta: float = 1.0
    gamma: float = 1.0
    mu1: float = 3.0
    mu2: float = 3.0
    _NAME: ClassVar[str] = "upsampling.multipliers"
    _CHECKS: ClassVar[dict] = dict.fromkeys(("lam", "eta", "gamma", "mu1", "mu2"), positive)


@dataclass(frozen=True)
class UpsamplingConfig(Group):
    """Guided upsampling: x⁰ on the fine grid (``init``: ``"jbu"`` held within ``init_band`` noise σ plus
    ``init_edge_band`` times the depth-edge evidence of bicubic interpolation, refused where ``K(jbu)`` leaves the
    input by ``init_consistency`` σ more than bicubic does; or ``"bicubic"``) and the layer weights' policy: each
    times its multiplier, λ divided by the factor with ``tv_per_factor``."""

    init: str = "jbu"
    init_band: float = 3.0
    init_edge_band: float = 0.5
    init_consistency: float = 2.0
    tv_per_factor: bool = True
    jbu: JBUConfig = field(default_factory=JBUConfig)
    multipliers: LayerMultipliers = field(default_factory=LayerMultipliers)
    _NAME: ClassVar[str] = "upsampling"
    _CHECKS: ClassVar[dict] = {"init": choice("jbu", "bicubic"), "init_band": non_negative,
                               "init_edge_band": non_negative, "init_consistency": non_negative,
                               "tv_per_factor": boolean}
    _NESTED: ClassVar[dict] = {"jbu": JBUConfig, "multipliers": LayerMultipliers}


@dataclass(frozen=True)
class OutputHold(Group):
    """Do no harm (guided upsampling): the output held within ``band`` · n + ``edge`` · max(E − ``edge_threshold``
    · σ̂, 0) of x⁰ rebuilt with the white-noise level n (:func:`~torch_depth_sr.upsampling.hold_to_initial`)."""

    band: float = 3.0
    edge: float = 1.0
    edge_threshold: float = 16.0
    _NAME: ClassVar[str] = "upsample_hold"
    _CHECKS: ClassVar[dict] = {"band": positive, "edge": non_negative, "edge_threshold": non_negative}


@dataclass(frozen=True)
class EdgeSnap(Group):
    """Edge snapping of the output on samples with outliers (:func:`~torch_depth_sr.edge_snap.snap_to_sides`):
    ``rounds`` passes of "x ← the colour-weighted median of its (2 radius + 1)² window where the weight on the
    median's side exceeds ``share``" (colour weights exp(−‖Δc‖₁/``sigma_color``), times a Gaussian of
    ``sigma_space`` px; None = a flat window), where the 5×5 range of x exceeds ``edge`` noise σ (None: at every
    pixel)."""

    rounds: int = 1
    radius: int = 2
    share: float = 0.6
    sigma_color: float = 0.235
    sigma_space: Optional[float] = None
    edge: Optional[float] = None
    _NAME: ClassVar[str] = "edge_snap"
    _CHECKS: ClassVar[dict] = {"rounds": integer(1), "radius": integer(1),
                               "share": real(0.5, 1.0, lo_open=False, hi_open=True), "sigma_color": positive,
                               "sigma_space": optional(positive), "edge": optional(non_negative)}


@dataclass(frozen=True)
class EdgeRefit(Group):
    """On samples with outliers, where the 5×5 range of x exceeds ``edge`` noise σ: x ← the colour-weighted median
    of the measurements within ``band`` σ of x in a (2 radius + 1)² window
    (:func:`~torch_depth_sr.edge_snap.refit_to_measurements`)."""

    radius: int = 5
    band: float = 1.5
    edge: float = 2.0
    sigma_color: float = 0.235
    _NAME: ClassVar[str] = "edge_refit"
    _CHECKS: ClassVar[dict] = {"radius": integer(1), "band": positive, "edge": non_negative,
                               "sigma_color": positive}


@dataclass(frozen=True)
class Guidance(Group):
    """Per-pixel multipliers in [1/range, range] of each layer's thresholds from a small CNN
    (:class:`~torch_depth_sr.guidance.GuidanceNet`, ``channels`` wide); zero-initialised, trained with the layers."""

    channels: int = 16
    range: float = 4.0
    _NAME: ClassVar[str] = "guidance"
    _CHECKS: ClassVar[dict] = {"channels": integer(1), "range": real(1.0, lo_open=False)}


@dataclass(frozen=True)
class Refiner(Group):
    """The learned, clamped edge correction after the model (:class:`~torch_depth_sr.refiner.EdgeRefiner`):
    ``channels`` wide, ``layers`` hidden convolutions, for the ``task`` it was trained for."""

    channels: int = 32
    layers: int = 6
    task: str = "upsample"
    _NAME: ClassVar[str] = "refiner"
    _CHECKS: ClassVar[dict] = {"channels": integer(1), "layers": integer(0),
                               "task": choice("upsample", "denoise")}


@dataclass(frozen=True)
class StreamConfig(Group):
    """The state a :class:`~torch_depth_sr.stream.StreamRestorer` carries from frame to frame
    (:mod:`torch_depth_sr.stream`; ``None``, the default: every frame on its own). Distances are in local noise
    levels (the spread of the measurements about the estimate), colour in [0, 1], sizes in pixels.

    The change test (:func:`~torch_depth_sr.stream.change_test`) calls a pixel *changed* when, in the ``window``
    around it, the mean colour change exceeds ``color_test`` (the frame's median change removed), most measurements
    lie farther than ``depth_test`` from the previous estimate; changed pixels are dilated by ``dilate``. When the
    colour image as a whole shifted (its change falls below ``camera_test`` times the unshifted change; None = never),
    the camera moved and every pixel is changed. A measured pixel is changed too where its 5×5 window departs from the
    previous estimate (a pixel 4 units off, the unit at least 2 σ̂) and one of that estimate's one-pixel shifts
    matches the window with less than ``shift_test`` times the unshifted error (:mod:`~torch_depth_sr.stream.shift`:
    an edge that moved by a pixel, which the depth test's one-pixel tolerance does not see; None = never). A pixel
    is changed too where the measurements of its 5×5 window drift from their runs' means: each adds its departure
    in noise units, clipped to ±1, and the sum exceeds ``drift_test`` times the root of their count (a z-score),
    where the window's colour changed by at least half ``color_test`` (a slanted surface sliding by a pixel or two a
    frame, which the depth test's one-pixel tolerance passes; a real sensor's depth drifts so on a still scene, but
    its colour stays; :func:`~torch_depth_sr.stream.change.drifting`; None = never; no test without colour).
    In a static window a measurement that matches no previous value
    near it by ``outlier_test`` is an outlier in time, dropped where the past was measured, unless it repeats the
    previous frame's dropped or held-out value (None = never). One that left the mean of its run by as much is held
    out the first time, the pixel keeping the mean (a mixed pixel at a depth edge takes the other side's depth in
    single frames). A repeated value starts a new run: a new mean and, in that frame, no temporal pull.

    On a static pixel the model sees the mean of the run's measurements (``y``), and the layers pull x to the
    previous estimate with ``weight`` times the pixel's age (:class:`~torch_depth_sr.terms.TemporalPriorTerm`); the
    age counts the frames of the static run, at most ``max_frames`` (``unmeasured_frames`` on a hole the past did
    not measure: its fill follows the frame's own). The evidence counts the trusted measurements of the run and
    decays by ``hole_decay`` per frame without one; a hole with evidence of at least ``fill_evidence`` is filled
    from the past and counts as a confident fill. With ``reuse_matches`` the pixels whose matches lie in static
    parts keep the previous frame's matches. A frame with a previous frame runs the model's first ``layers`` layers on
    the whole frame and the others on the pixels that changed or whose static run is younger than ``max_frames``
    alone (:mod:`~torch_depth_sr.stream.later_layers`; None: every layer everywhere). With ``keep_scale`` a
    frame is normalised with the previous frame's scale policy (offset, scale, noise σ̂, grid step) while at least half
    of the previous frame was static, instead of estimating them again. ``join_cap`` bounds the noise unit a
    measurement is compared with to its run's mean (joined, held out or confirmed), in units of the change test's
    floor (a quarter of the frame's σ̂, or its quantisation step; None = no bound): a moving edge inflates the local
    unit, and without the bound a mover's new measurements joined the mean of the background it covered.

    A static pixel whose run has its full mean keeps its previous output while the layers' value there stays within
    ``hold`` noise units (``join_cap``'s bounded unit) of the value that output was computed from, on frames whose
    singular gate switches the edge steps on (sensor input with flying pixels): the post-steps (edge snap, edge
    refit, the refiner) act on the other pixels only, which there is most of what a step saves
    (:mod:`~torch_depth_sr.stream.post_hold`; None = the post-steps everywhere). Nothing is held
    while a gradient is tracked (training). "Its full mean" is a static run of at least ``settled_frames`` frames (None:
    ``max_frames``): where the later layers and the post-steps may leave a pixel to its past.

    A measurement of this frame alone (not a run's mean: a changed pixel, a new run) is trusted only with at least
    ``single_support`` measured 8-neighbours within ``SingularConfig.support_tol`` or on a line
    (``SingularConfig.line_support``), whatever the singular test says: a flying pixel at a mover floats alone (None:
    no such rule; nothing without a singular test)."""

    # weight and max_frames fitted with the fast tier on static streams of the 2006 scenes (docs/measurements/
    # issue28-stream/fit_stream_2006.py: the lowest error among the settings that leave no scene worse than frame by
    # frame; 2 and 16 before, fitted on the synthetic tuning sequences alone, drifted to +16 % on Wood1), checked on
    # the tuning sequences (no worse than frame by frame in RMSE and trail there)
    weight: float = 0.5
    max_frames: float = 8.0
    # 0: a hole the past never measured confidently gets no pull to the past (its fill is the frame's own). 2 until the
    # thirty-second stop: beside a moving object such a hole (a stereo shadow) was pulled to where the mover was, and
    # with fill="trusted" the stream showed more wrong fills near movers than frame by frame at 480×640; RMSE, flicker
    # and trail of the 60 synthetic fitting sequences within 0.3 % of 2's (docs/measurements/issue28-stream/
    # thirty-second-stop/)
    unmeasured_frames: float = 0.0
    hole_decay: float = 0.8
    fill_evidence: float = 1.0
    depth_test: float = 2.0
    outlier_test: Optional[float] = 4.0
    color_test: float = 0.03
    camera_test: Optional[float] = 0.8
    window: int = 3
    dilate: int = 2
    reuse_matches: bool = True
    keep_scale: bool = True
    # 80 floors (20 σ̂): of 16, 40, 80 and 160 floors, on an enlarged tuning set, the lowest mean RMSE among those that
    # leave no scene's RMSE above frame by frame's and the flicker and trail within 0.5 % of no bound's
    # (docs/measurements/issue28-stream/nineteenth-stop/join_cap_tuning.py)
    join_cap: Optional[float] = 80.0
    # of 0.3, 0.5 and 0.7, on 45 synthetic sequences (the tuning ones and the recipes' seeds 300-303 and 400-409):
    # the lowest mean trail among those that leave no sequence's RMSE above frame by
    # frame's and the mean flicker at most the stream's without the test (docs/measurements/issue28-stream/
    # twentieth-stop/shift_test_tuning.py)
    shift_test: Optional[float] = 0.5
    # a z-score (5 never fires: a full window's sum is at most 25 = 5·√25). Before its colour gate, of 3, 4 and 5 on the
    # 15 fitting sequences at 480×640 (the tuning ones and seeds 300-303): the lowest mean trail whose mean flicker
    # stays within 0.5 % of no test's (3: +3.7 %). With the gate (docs/measurements/issue28-stream/thirty-first-stop/):
    # 3 and 4 give the same mean trail over those and the 45 fitting sequences at 120×160 (0.8854), 4 the lower RMSE
    # and flicker at 120×160; at 480×640 RMSE 0.704 -> 0.689, trail 0.910 -> 0.880 of frame by frame's, flicker the same
    drift_test: Optional[float] = 4.0
    # the speed against the accuracy: of 0.05, 0.1, 0.25, 0.5, 1 and 2, the largest whose 2006 streams (fitting split)
    # stay within 0.5 % of no hold's mean ratio to frame by frame and whose 45 synthetic fitting sequences are no worse
    # in the mean RMSE, flicker and trail. Refitted at the twenty-eighth stop, when outputs became held only while the
    # edge steps act: every value passes on the 2006 streams, and the trail is 0.05-0.12 % longer than no hold's from
    # 0.5 up (a 640×480 step on moving sensor input 0.58 cold frames at 0.25, 0.55 at 0.5 in a stage script;
    # docs/measurements/issue28-stream/twenty-eighth-stop/). 0.1 until then (0.25 had cost 1.3 % on the 2006 streams)
    hold: Optional[float] = 0.25
    layers: Optional[int] = None
    # None (max_frames): 1 (every static pixel settled: later layers only where the scene changed) made a 640×480 step
    # on moving sensor input 0.75 cold frames instead of 0.81 and the 45 synthetic fitting sequences better, but the
    # 2006 streams (fitting split) 5 % worse on the mean of the four groups (4: 1.7 % worse; docs/measurements/
    # issue28-stream/twenty-second-stop/)
    settled_frames: Optional[float] = None
    # of 1, 2 and 3 on the 45 synthetic fitting sequences (120×160): 1, the lowest RMSE and flicker (0.703 and 0.380 of
    # frame by frame's, against 0.761 and 0.394 without the rule), the trail within 0.3 % of the shortest (0.905
    # against 0.989; longer than frame by frame's in 1 sequence instead of 14); 2 and 3 also left more well-measured
    # pixels of a slow mover far off (test_stream_known_limits: 204 and 247 against 167, 164 without the rule)
    # (docs/measurements/issue28-stream/twenty-sixth-stop/)
    single_support: Optional[int] = 1
    _NAME: ClassVar[str] = "stream"
    _CHECKS: ClassVar[dict] = {"weight": positive, "max_frames": positive, "unmeasured_frames": non_negative,
                               "hole_decay": real(0.0, 1.0, False), "fill_evidence": positive,
                               "depth_test": positive, "camera_test": optional(real(0.0, 1.0)),
                               "outlier_test": optional(positive), "color_test": positive,
                               "window": integer(1, odd=True), "dilate": integer(0), "reuse_matches": boolean,
                               "keep_scale": boolean, "join_cap": optional(positive),
                               "shift_test": optional(real(0.0, 1.0)), "drift_test": optional(positive),
                               "hold": optional(positive),
                               "layers": optional(integer(1)), "settled_frames": optional(positive),
                               "single_support": optional(integer(1))}

    def settled_age(self) -> float:
        """The age from which a static run is settled (not ``fresh``): ``settled_frames``, or ``max_frames``."""
        return self.max_frames if self.settled_frames is None else self.settled_frames
