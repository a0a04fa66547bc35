""":class:`StreamRestorer`: a depth video restored frame by frame with state carried from one frame to the next.

What a frame leaves for the next (:class:`StreamState`): the restored depth; per pixel the *age* (frames of its
static run), the *evidence* (trusted measurements of the run, decaying over holes), the mean of the run's
measurements, whether the output had a value, the confidence, the local noise spread; the colour image and the last
matches. The model's :meth:`~torch_depth_sr.DepthRestorer._run` calls the five hooks of :class:`_Frame`:

1. ``observe`` — the change test (:func:`~torch_depth_sr.stream.change.change_test`) splits static from changed
   pixels (a moving object, what it uncovers, a moved camera); outliers in time are dropped where the past was
   measured; on static pixels ``y`` becomes the mean of the run's measurements (a measurement that left it is held
   out); a dropped or held-out value that the next frame measures again starts a new run; the temporal prior
   (``obs.temporal``: the previous estimate and the weight ``settings.weight × age`` on static pixels, read by
   :class:`~torch_depth_sr.terms.TemporalPriorTerm` in every layer) and the matcher that keeps the previous matches
   where they lie in static parts (:class:`~torch_depth_sr.stream.matching.StreamMatcher`);
2. ``initial`` — the model's initial stage, then the verdict of each hole for ``fill="trusted"``: filled from a
   confident past (evidence ≥ ``fill_evidence``), or the previous frame's verdict while the pixel stays a hole of
   unchanged colour, else the frame's own (no pixel toggles on noise, no gap is bridged that the frame would not);
3. ``run_layers`` — the layers: with a previous frame and ``settings.layers = n``, the first ``n`` on the whole
   frame and the others only where the scene changed or the static run is younger than ``max_frames``, on crops
   around those pixels (:mod:`~torch_depth_sr.stream.crop_layers`; None, the default: every layer on the whole
   frame);
4. ``post`` — the post-steps, except on static pixels with a full run whose layers' value stayed within
   ``settings.hold`` of the value their previous output came from: those keep that output
   (:mod:`~torch_depth_sr.stream.post_hold`);
5. ``keep`` — the state for the next frame.

A frame with no state (the first after construction or :meth:`StreamRestorer.reset`) is the per-frame model's,
bit for bit. The state is kept without gradient (truncated back-propagation through time: a training step's
gradient flows through the current frame only). ``docs/stream.md`` has the measurements.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, fields, replace
from typing import Any, NamedTuple, Optional, Union

import torch
from torch import nn

from .._inputs import map_layout, parse_depth, restore_layout
from ..config import StreamConfig
from ..errors import ShapeError
from ..initial import InitialEstimate
from ..model import DepthRestorer, NoiseSigma, _check_fill, _check_model_input, _is_integer_dtype
from ..noise import sampled_noise_sigma
from ..observation import Observation, ScalePolicy
from ..state import RestorationState
from ..terms import TemporalPriorTerm
from .change import change_test, local_spread, remembered_spread
from .crop_layers import run_later_layers
from .matching import StreamMatcher, dilate, search_radius
from .post_hold import run_post_steps
from .runs import grow_runs, join_runs

__all__ = ["DEFAULT_STREAM_MODEL", "StreamRestorer", "StreamResult", "StreamState", "TemporalPrior",
           "default_stream_model", "with_stream"]


SPREAD_MEMORY = 0.9  # the decay per frame of the remembered frame-to-frame change (the change test's noise unit)
# the shift test's unit is at least this many of the change test's floors (2 σ̂, or 8 quantisation steps): with the
# floor alone (a quarter of σ̂) a still RealSense scene's noise found shifts in a fifth of its windows. Of 1, 4, 8 and 16
# floors, the lowest mean error on the 2006 streams with a mover (sensor), the synthetic fitting set alike for all
# (docs/stream.md, item 8)
SHIFT_FLOOR = 8.0


class TemporalPrior(NamedTuple):
    """What a stream frame knows of the previous one (``obs.temporal``), on the observation grid, in its units."""

    target: torch.Tensor  # (B,1,H,W) the previous restored depth, normalised as this frame
    weight: torch.Tensor  # (B,1,H,W) the prior's weight: settings.weight × age on static pixels, else 0
    static: torch.Tensor  # (B,1,H,W) bool: the change test found nothing
    evidence: torch.Tensor  # (B,1,H,W) the previous frame's evidence
    averaged: torch.Tensor  # (B,1,H,W) bool: y is the mean of the static run's measurements here
    restarted: torch.Tensor  # (B,1,H,W) bool: a static pixel whose measurement left the run's mean (a new mean)
    seen: torch.Tensor  # (B,1,H,W) bool: the colour changed here (without colour: the change test)


@dataclass
class StreamState:
    """What one frame leaves for the next (no gradient), in depth units."""

    depth: torch.Tensor  # (B,1,H,W) the restored depth (every hole filled)
    age: torch.Tensor  # (B,1,H,W) frames of the static run behind each pixel, at most max_frames
    evidence: torch.Tensor  # (B,1,H,W) trusted measurements of the static run (decaying over holes)
    mean: torch.Tensor  # (B,1,H,W) the mean of the run's measurements (0: none)
    valid: torch.Tensor  # (B,1,H,W) bool: the output had a value (measured, or a confident fill)
    hole: torch.Tensor  # (B,1,H,W) bool: not measured (or an outlier in time)
    confidence: torch.Tensor  # (B,1,H,W) the model's confidence where measured, decayed on holes filled from the past
    spread: torch.Tensor  # (B,1,H,W) local mean |y − x| of the measurements about the restored depth
    rgb: Optional[torch.Tensor]  # (B,3,H,W) the colour image
    matches: Optional[tuple[torch.Tensor, torch.Tensor]]  # the last layer's (dist, index), or None
    departed: torch.Tensor  # (B,1,H,W) a measurement held out as the first departure from its run's mean (0: none)
    match_weights: Optional[tuple[torch.Tensor, torch.Tensor]] = None  # the matches' weights, the temperature
    policy: Optional[ScalePolicy] = None  # the observation's scale policy (offset, scale, σ, grid step, percentiles)
    static_share: float = 1.0  # the share of static pixels (1 on a first frame: it found nothing changed)
    anchor: Optional[torch.Tensor] = None  # (B,1,H,W) the layers' value the output came from (settings.hold)


class StreamResult(NamedTuple):
    """:meth:`StreamRestorer.step` with ``return_details=True``: :class:`~torch_depth_sr.RestorationResult`'s fields,
    then the stream's own maps, all in the input's array type and layout.

    ``confidence`` is the singular test's P at measured pixels and, on a hole filled from the past, the confidence
    the pixel had when it was last measured times ``hole_decay`` per frame since (0 on other holes). ``static``: the
    change test found nothing (all False on the first frame); ``evidence``: the trusted measurements behind each
    pixel after this frame. ``info["stream"]`` holds the frame's index in the stream and the shares of static pixels,
    reused matches, holes filled from the past and held outputs (``held``, :mod:`~torch_depth_sr.stream.post_hold`)."""

    depth: Any
    confidence: Any
    trusted: Any
    outliers: Any
    info: dict
    static: Any
    evidence: Any


def with_stream(model: DepthRestorer, settings: StreamConfig) -> DepthRestorer:
    """``model`` with the stream's :class:`~torch_depth_sr.terms.TemporalPriorTerm` in its layers (config group
    ``stream`` = ``settings``), sharing every parameter, buffer and stage with ``model``: training either trains
    both. ``model`` itself is unchanged (its frames stay the per-frame model's); a model whose config already holds
    ``settings`` is returned as it is."""
    if model.config.stream == settings:
        return model
    variant = _shallow(model)
    variant.config = model.config.replace(stream=settings)
    layers = []
    for layer in model.layers:
        lv = _shallow(layer)
        terms = _shallow(layer.terms)
        own = [t for t in layer.terms["denoise"] if not isinstance(t, TemporalPriorTerm)]
        terms["denoise"] = nn.ModuleList([*own, TemporalPriorTerm(settings)])
        lv.terms = terms
        layers.append(lv)
    variant.layers = nn.ModuleList(layers)
    return variant


def _shallow(module: nn.Module) -> nn.Module:
    """A new module object sharing ``module``'s submodules, parameters and buffers (its own registries)."""
    out = copy.copy(module)
    for name in ("_modules", "_parameters", "_buffers"):
        object.__setattr__(out, name, dict(getattr(module, name)))
    return out


def _stream_settings(model: DepthRestorer, settings: Union[StreamConfig, dict, None]) -> StreamConfig:
    base = model.config.stream or StreamConfig()
    if settings is None:
        return base
    if isinstance(settings, dict):
        return base.replace(**settings)
    if not isinstance(settings, StreamConfig):
        from ..errors import ParameterError

        raise ParameterError("settings", settings, "a StreamConfig, a dict of its fields or None")
    return settings


class _Frame:
    """The stream hooks of :meth:`DepthRestorer._run` for one frame: the previous frame into the observation and
    the initial stage, this frame kept for the next (:attr:`kept`)."""

    def __init__(self, settings: StreamConfig, state: Optional[StreamState], index: int = 0):
        self.settings, self.state, self.index = settings, state, index
        self.kept: Optional[StreamState] = None
        self.valid: Optional[torch.Tensor] = None
        self.stats: dict = {}
        self.static: Optional[torch.Tensor] = None
        self.departed: Optional[torch.Tensor] = None  # this frame's held-out departures (observe), in depth units
        self.fresh: Optional[torch.Tensor] = None  # changed, or a static run younger than max_frames (observe)
        self.warm = False  # this frame has the previous one's prior (observe found state on a denoising task)
        self.layers_x: Optional[torch.Tensor] = None  # the layers' value, before the post-steps (post)
        self.steady: Optional[torch.Tensor] = None  # the pixels whose previous output is held (post)
        self.unit: Optional[torch.Tensor] = None  # the bounded noise unit of the runs (observe), normalised

    def scale_policy(self, y: torch.Tensor, observed: torch.Tensor, noise_sigma: NoiseSigma) -> Optional[ScalePolicy]:
        """The previous frame's scale policy while at least half of that frame was static (``keep_scale``): a
        static scene's offset, scale and noise level stay what they were, and estimating them again cost about a tenth
        of a step (docs/measurements/issue28-stream/history.md, item 6); else None, estimated again. A
        ``noise_sigma`` the caller gives sets σ in :func:`~torch_depth_sr.observation.observe`: no estimate is made
        then."""
        st = self.state
        if (st is None or not self.settings.keep_scale or st.policy is None or st.static_share < 0.5
                or st.policy.offset.shape[0] != y.shape[0]):
            return None
        policy = ScalePolicy(*(t.to(device=y.device, dtype=y.dtype) for t in st.policy))
        if noise_sigma is not None:
            return policy
        # the noise level: a running mean of estimates from a quarter of the rows each frame (the rows cycle)
        sampled = sampled_noise_sigma(y, observed, 1 + self.index % 4)
        sigma = torch.where(sampled > 0, 0.75 * policy.sigma + 0.25 * sampled, policy.sigma)
        return policy._replace(sigma=torch.maximum(sigma, policy.step / 12**0.5))

    def observe(self, obs: Observation) -> Observation:
        s, st = self.settings, self.state
        if st is None or obs.task != "denoise":
            return obs
        if st.depth.shape != obs.y.shape:
            raise ShapeError(f"this frame is {tuple(obs.y.shape)} but the stream's previous frame was "
                             f"{tuple(st.depth.shape)}; call reset() before a stream of another size or batch.",
                             actual=tuple(obs.y.shape), expected=tuple(st.depth.shape))
        dt = obs.y.dtype
        target = obs.normalise(st.depth.to(dt))
        scale = obs.scale.to(dt).view(-1, 1, 1, 1)
        floor = torch.maximum(0.25 * obs.noise, obs.grid_step).to(dt).view(-1, 1, 1, 1)
        noise = torch.maximum(st.spread.to(dt) / scale, floor)
        # the run's mean and the shift test read a unit an edge cannot inflate without bound (join_cap)
        joining = noise if s.join_cap is None else torch.minimum(noise, s.join_cap * floor)
        test = change_test(obs.y, obs.observed, target, noise, obs.rgb, st.rgb, s,
                           shift_noise=torch.maximum(joining, SHIFT_FLOOR * floor))
        static = ~test.changed
        if test.own is not None:  # a hole has no depth to test: its own colour must not change
            static = static & ~(test.own & (obs.observed <= 0))
        evidence = st.evidence.to(dt)
        runs = join_runs(obs.y, obs.observed, static, test.outlier, joining, evidence, st.mean.to(dt),
                         st.departed.to(dt), st.age.to(dt), obs.offset, obs.scale, s)
        self.stats["outliers_in_time"] = float(runs.outlier.float().mean())
        self.stats["held_out"] = float(runs.held_out.float().mean())
        glitches = obs.glitches | runs.outlier if bool(runs.outlier.any()) else obs.glitches
        # the singular gate also reads the pixels measured in this frame alone: the runs' means hide the past's
        # flying pixels, and with them a mover's fell below the gate (stages._gate)
        obs = replace(obs, y=runs.y, observed=runs.observed, glitches=glitches, gate_region=~runs.averaged)
        self.departed = runs.departed.detach()
        self.static, self.warm, self.fresh = static, True, runs.fresh
        self.unit = joining
        obs = replace(obs, temporal=TemporalPrior(target, runs.weight, static, evidence, runs.averaged,
                                                  runs.restarted, test.seen))
        if s.reuse_matches and st.matches is not None:
            fresh = dilate(test.changed, search_radius(obs.block_matcher.settings, obs.task))
            obs = replace(obs, block_matcher=StreamMatcher(obs.block_matcher, st.matches, fresh, st.match_weights))
            self.stats["reused_matches"] = float((~fresh).float().mean())
        return obs

    def initial(self, init: nn.Module, obs: Observation) -> InitialEstimate:
        initial = init(obs)
        prior = obs.temporal
        hole = obs.observed <= 0
        if prior is None:
            self.valid = ~hole | (initial.fill_confident > 0)
            return initial
        # a hole the past measured confidently is filled from the past; a hole that was one in the previous frame
        # too keeps that frame's verdict (filled, or left missing with fill="trusted") unless its colour changed: no
        # pixel toggles between filled and missing on noise; any other hole gets the frame's own verdict
        past = self._from_past(obs)
        held = hole & self.state.hole.to(hole.device) & ~prior.seen
        confident = torch.where(past, torch.ones_like(initial.fill_confident),
                                torch.where(held, self.state.valid.to(initial.fill_confident), initial.fill_confident))
        self.valid = ~hole | (confident > 0)
        return initial._replace(fill_confident=confident)

    def run_layers(self, layers: nn.ModuleList, state: RestorationState, obs: Observation) -> RestorationState:
        n = self.settings.layers
        first = layers if not self.warm or n is None else layers[:n]
        for layer in first:
            state = layer(state, obs)
        if len(first) < len(layers):
            # the rest of the layers where the scene changed or the static run has not yet its full mean
            # (max_frames measurements): on crops around those pixels (crop_layers)
            state = run_later_layers(layers[len(first):], state, obs, self.fresh)
        return state

    def post(self, steps: nn.ModuleList, x: torch.Tensor, state: RestorationState, obs: Observation,
             initial: InitialEstimate) -> torch.Tensor:
        """The post-steps; with ``settings.hold`` on a warm frame a static pixel whose run has its full mean keeps its
        previous output while the layers' value ``x`` stays within ``hold`` units of the value that output came from
        (:mod:`~torch_depth_sr.stream.post_hold`). Not while a gradient is tracked through ``x`` (training): every
        pixel's loss then reaches the parameters."""
        self.layers_x = x.detach()
        st, hold = self.state, self.settings.hold
        training = torch.is_grad_enabled() and x.requires_grad  # a held output would carry no gradient: none held
        if hold is not None and self.warm and st.anchor is not None and not training:
            anchor = obs.normalise(st.anchor.to(x))
            self.steady = ~self.fresh & ((self.layers_x - anchor).abs() <= hold * self.unit)
            self.stats["held"] = float(self.steady.float().mean())
        return run_post_steps(steps, x, state, obs, initial, self.steady,
                              None if self.steady is None else obs.temporal.target)

    def _anchor(self, x: torch.Tensor, obs: Observation) -> torch.Tensor:
        """(B,1,H,W) depth units: the layers' value each output was computed from (kept where the output was held)."""
        now = obs.denormalise(self.layers_x.to(x))
        return now if self.steady is None else torch.where(self.steady, self.state.anchor.to(x), now)

    def _from_past(self, obs: Observation) -> torch.Tensor:
        """Holes the past measured confidently: static, with evidence of at least ``fill_evidence``."""
        prior = obs.temporal
        return (obs.observed <= 0) & prior.static & (prior.evidence >= self.settings.fill_evidence)

    def keep(self, x: torch.Tensor, state: Any, obs: Observation, initial: InitialEstimate) -> None:
        s = self.settings
        if obs.task != "denoise":
            self.kept = None
            return
        with torch.no_grad():
            x = x.detach()
            measured = obs.observed > 0
            trusted = measured & (state.q.detach() > 0)
            conf = (state.confidence.detach() * obs.observed).to(x.dtype)
            prior = obs.temporal
            if prior is None:
                one = trusted.to(x.dtype)
                ymean = torch.where(measured, obs.denormalise(obs.y.detach()), torch.zeros_like(x))
                age, evidence, confidence, mean = torch.ones_like(one), one, conf, ymean
            else:
                st = self.state
                runs = grow_runs(obs.y.detach().to(x.dtype), obs.observed.to(x.dtype), trusted, conf, prior.static,
                                 prior.restarted, prior.evidence.to(x.dtype), st.age.to(x.dtype),
                                 st.confidence.to(x.dtype), st.mean.to(x.dtype), obs.offset, obs.scale, s)
                age, evidence, confidence, mean = runs.age, runs.evidence, runs.confidence, runs.mean
                self.stats["filled_from_past"], self.stats["static"] = runs.filled_from_past, runs.static
            matches = weights = None
            if state.matches is not None:
                matches = (state.matches.dist.detach(), state.matches.index.detach())
                weights = (state.matches.weight.detach(), obs.block_matcher.temperature.detach().clone())
            rgb = None if obs.rgb is None else obs.rgb.detach()
            # the noise unit of the next change test: the local spread of the measurements about this estimate, and
            # where the scene stayed, of their change since the previous estimate (a sensor whose depth steps
            # between levels, far away, moves more from frame to frame than about any one estimate), remembered
            # with a decay of SPREAD_MEMORY per frame
            if prior is None:
                spread = local_spread(obs.raw, obs.observed, x, 2 * s.window + 1)
            else:
                spread = remembered_spread(obs.raw, obs.observed, x, self.state.depth.to(x), self.state.spread.to(x),
                                           prior.static, 2 * s.window + 1, SPREAD_MEMORY)
            self.kept = StreamState(depth=x, age=age, evidence=evidence, mean=mean, valid=self.valid, hole=~measured,
                                    confidence=confidence, spread=spread, rgb=rgb, matches=matches,
                                    departed=torch.zeros_like(x) if self.departed is None else self.departed,
                                    match_weights=weights, policy=ScalePolicy(*(t.detach() for t in obs.policy)),
                                    static_share=self.stats.get("static", 1.0),
                                    anchor=None if s.hold is None else self._anchor(x, obs))


DEFAULT_STREAM_MODEL = "denoise-fast"
"""The shipped model a stream runs without a model: the 3-layer ``denoise-fast`` (the ``fast`` tier until
2026-12-05). Its stream settings (``layers`` 1 in its config) were fitted for it, and every figure of
``docs/stream.md`` (the ``stream`` track's default ``--model``) is of it."""


def default_stream_model() -> DepthRestorer:
    """The model of ``StreamRestorer()`` and of a stream with no model named (``torch-depth-sr restore --stream``):
    ``DepthRestorer.from_pretrained(DEFAULT_STREAM_MODEL)``, on the CPU."""
    return DepthRestorer.from_pretrained(DEFAULT_STREAM_MODEL)


class StreamRestorer(nn.Module):
    """A depth video restored frame by frame, each frame helped by the previous one (module docstring).

    Args:
        model: the :class:`~torch_depth_sr.DepthRestorer` to run (``from_pretrained``, ``from_preset``, trained or
            frozen); default :func:`default_stream_model`, ``denoise-fast`` (the ``fast`` tier until 2026-12-05):
            the stream's settings were fitted for it and ``docs/stream.md`` measures it (a stream of another model,
            the ``fast`` tier's ``denoise-fast2`` too, runs with settings not fitted for it, and a step of the 8-layer
            tiers costs what a cold frame does). The stream shares its parameters (:func:`with_stream`): training the
            stream trains ``model``.
        settings: the stream's settings (:class:`~torch_depth_sr.config.StreamConfig`, a dict of changes, or None:
            ``model.config.stream``, else the defaults).
        fill: ``"all"`` or ``"trusted"`` as in :func:`~torch_depth_sr.restore_depth`; with ``"trusted"`` a hole
            filled from the past counts as confident.
        noise_sigma: the noise std in depth units (None: estimated per frame).

    :meth:`step` takes and returns what :func:`~torch_depth_sr.restore_depth` does (numpy or torch, ``(H,W)``,
    ``(1,H,W)`` or ``(B,1,H,W)``, any dtype and unit, 0/NaN holes); a batch is B independent streams. As a module,
    ``stream(depth, rgb)`` is :meth:`DepthRestorer.forward` with the state (``(B,1,H,W)`` float tensors,
    differentiable).
    :meth:`reset` starts a new stream. ``stateful`` tells :func:`~torch_depth_sr.recordings.restore_dataset` to replay
    a sequence from its start on resume.

    Examples:
        >>> from torch_depth_sr.datasets.synthetic import make_scene
        >>> s = make_scene(32, 40, seed=0)
        >>> stream = StreamRestorer(DepthRestorer(num_layers=2))
        >>> frames = [s["gt"] + torch.randn_like(s["gt"]) for _ in range(3)]
        >>> outs = [stream.step(f, s["rgb"]) for f in frames]
        >>> outs[-1].shape
        torch.Size([1, 32, 40])
    """

    stateful = True

    def __init__(self, model: Optional[DepthRestorer] = None, settings: Union[StreamConfig, dict, None] = None, *,
                 fill: str = "all", noise_sigma: NoiseSigma = None):
        super().__init__()
        model = default_stream_model() if model is None else model
        _check_fill(fill)
        self.settings = _stream_settings(model, settings)
        self.model = with_stream(model, self.settings)
        self.fill, self.noise_sigma = fill, noise_sigma
        self.state: Optional[StreamState] = None
        self.frames = 0  # frames since the last reset

    def _apply(self, fn, recurse=True):
        """``.to(device)``, ``.cuda()``, ``.cpu()`` move the stream's state with the model (the state is no registered
        buffer, so nn.Module would leave it behind and the next frame would mix devices). The state keeps its dtype:
        it is the frames' compute dtype (float64 input: float64, else float32), cast where it is read, not the
        model's, so ``.double()``/``.half()`` move only its device (``fn`` of an empty tensor tells where to)."""
        out = super()._apply(fn, recurse)
        st = self.state
        if st is not None:
            def move(t):
                if t is None or isinstance(t, (float, int)):
                    return t
                if isinstance(t, tuple):
                    return type(t)(*(move(v) for v in t)) if hasattr(t, "_fields") else tuple(move(v) for v in t)
                return t.to(fn(torch.empty(0, dtype=t.dtype, device=t.device)).device)
            self.state = StreamState(**{f.name: move(getattr(st, f.name)) for f in fields(st)})
        return out

    def reset(self) -> None:
        """Forget the previous frames: the next frame is restored on its own."""
        self.state = None
        self.frames = 0

    def step(self, depth: Any, rgb: Any = None, mask: Any = None, *, return_details: bool = False,
             fill: Optional[str] = None, noise_sigma: NoiseSigma = None, scale_factor: Optional[int] = None,
             timings: bool = False) -> Any:
        """Restore the next frame: ``depth``, ``rgb``, ``mask`` as :func:`~torch_depth_sr.restore_depth` takes them;
        returns the restored depth in the input's type, layout, dtype and units, or a :class:`StreamResult` with
        ``return_details=True``. ``fill`` and ``noise_sigma`` override the stream's for this frame."""
        fill = self.fill if fill is None else fill
        _check_fill(fill)
        dtype = depth.dtype if isinstance(depth, torch.Tensor) and depth.dtype == torch.float64 else torch.float32
        y, observed, layout = parse_depth(depth, mask, dtype)
        out, frame = self._step(y, observed, rgb, noise_sigma, scale_factor, fill, bool(timings) and return_details,
                                _is_integer_dtype(layout.dtype))
        x = restore_layout(out.depth, layout)
        if not return_details:
            return x
        maps = {k: map_layout(v, layout) for k, v in self._maps(out, frame).items()}
        return StreamResult(depth=x, info=out.info, **maps)

    def forward(self, depth: torch.Tensor, rgb: Optional[torch.Tensor] = None, mask: Optional[torch.Tensor] = None,
                noise_sigma: NoiseSigma = None, fill: Optional[str] = None) -> torch.Tensor:
        """The next frame of ``(B,1,H,W)`` float depth guided by ``rgb (B,3,H,W)`` in [0,1], as
        :meth:`DepthRestorer.forward` returns it (differentiable in the model's parameters)."""
        fill = self.fill if fill is None else fill
        _check_fill(fill)
        _check_model_input(depth, rgb, mask)
        dtype = torch.float64 if depth.dtype == torch.float64 else torch.float32
        y, observed, _ = parse_depth(depth, mask, dtype)
        out, _ = self._step(y, observed, rgb, noise_sigma, None, fill, False, False)
        return out.depth.to(device=depth.device, dtype=depth.dtype)

    def _step(self, y, observed, rgb, noise_sigma, scale_factor, fill, timed, integer_input):
        frame = _Frame(self.settings, self.state, self.frames)
        sigma = self.noise_sigma if noise_sigma is None else noise_sigma
        out = self.model._run(y, observed, rgb, sigma, scale_factor, fill, timed=timed, integer_input=integer_input,
                              stream=frame)
        self.state = frame.kept
        out.info["stream"] = {"frame": self.frames, **frame.stats}
        self.frames += 1
        return out, frame

    def _maps(self, out, frame: _Frame) -> dict:
        kept = frame.kept
        conf = out.confidence if kept is None else kept.confidence.to(out.confidence)
        static = torch.zeros_like(out.trusted, dtype=torch.bool) if frame.static is None else frame.static
        evidence = torch.zeros_like(out.trusted) if kept is None else kept.evidence.to(out.trusted)
        dev = out.trusted.device
        return {"confidence": conf.to(dev), "trusted": out.trusted, "outliers": out.outliers,
                "static": static.to(dev).to(out.trusted.dtype), "evidence": evidence.to(dev)}

    def extra_repr(self) -> str:
        return ", ".join(f"{k}={v}" for k, v in self.settings.to_dict().items()) + f", fill={self.fill!r}"
