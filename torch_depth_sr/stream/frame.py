"""The hooks of one stream frame (:class:`StreamFrame`) in :meth:`~torch_depth_sr.DepthRestorer._run`, and what a
frame leaves for the next (:class:`StreamState`).

What a frame leaves: the restored depth; per pixel the *age* (frames of its static run), the *evidence* (trusted
measurements of the run, decaying over holes), the mean of the run's measurements, whether the output had a value, the
confidence, the local noise spread; the colour image and the last matches. The five hooks:

1. ``observe`` — the change test (:func:`~torch_depth_sr.stream.change.change_test`) splits static from changed
   pixels (a moving object, what it uncovers, a moved camera); outliers in time are dropped where the past was
   measured; on static pixels ``y`` becomes the mean of the run's measurements (a measurement that left it is held
   out); a dropped or held-out value that the next frame measures again starts a new run; the temporal prior
   (``obs.temporal``: the previous estimate and the weight ``settings.weight × age`` on static pixels, read by
   :class:`~torch_depth_sr.terms.TemporalPriorTerm` in every layer) and the matcher that keeps the previous matches
   where they lie in static parts (:class:`~torch_depth_sr.stream.matching.StreamMatcher`); the pixels measured in
   this frame alone are read by the singular gate on their own and, with ``settings.single_support``, trusted only
   with the support of their neighbours (``obs.gate_region``, ``obs.untrusted``);
2. ``initial`` — the model's initial stage, then the verdict of each hole for ``fill="trusted"``: filled from a
   confident past (evidence ≥ ``fill_evidence``), or the previous frame's verdict while the pixel stays a hole of
   unchanged colour, else the frame's own (no pixel toggles on noise, no gap is bridged that the frame would not);
3. ``run_layers`` — the layers: with a previous frame and ``settings.layers = n``, the first ``n`` on the whole
   frame and the others only where the scene changed or the static run is younger than ``max_frames``: they update
   those pixels alone, every other pixel held at its state (:mod:`~torch_depth_sr.stream.later_layers`; None, the
   default: every layer on the whole frame);
4. ``post`` — the post-steps, except on static pixels with a full run whose layers' value stayed within
   ``settings.hold`` of the value their previous output came from, while the edge steps act: those keep that
   output (:mod:`~torch_depth_sr.stream.post_hold`);
5. ``keep`` — the state for the next frame.

A frame with no state (the first of a stream) is the per-frame model's, bit for bit. The state is kept without
gradient (truncated back-propagation through time: a training step's gradient flows through the current frame
only). ``docs/stream.md`` has the measurements.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, NamedTuple, Optional, Union

import torch
from torch import nn

from ..config import SingularConfig, StreamConfig
from ..errors import ShapeError
from ..initial import InitialEstimate
from ..model import NoiseSigma
from ..native import host_path
from ..noise import sampled_noise_sigma
from ..observation import Observation, ScalePolicy
from ..stages import supported_pixels
from ..state import RestorationState
from ..window_max import dilate
from .change import change_test, local_spread, remembered_spread
from .later_layers import run_later_layers
from .matching import StreamMatcher, search_radius
from .post_hold import run_post_steps
from .runs import grow_runs, join_runs

__all__ = ["SHIFT_FLOOR", "SPREAD_MEMORY", "StreamFrame", "StreamState", "TemporalPrior"]

SPREAD_MEMORY = 0.9  # the decay per frame of the remembered frame-to-frame change (the change test's noise unit)
# the shift test's unit is at least this many of the change test's floors (2 σ̂, or 8 quantisation steps): with the
# floor alone (a quarter of σ̂) a still RealSense scene's noise found shifts in a fifth of its windows. Of 1, 4, 8 and
# 16 floors, the lowest mean error on the 2006 streams with a mover (sensor), the synthetic fitting set alike for all
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
    # the share of static pixels (1 on a first frame: it found nothing changed); a 0-d tensor off the CPU kernels
    static_share: Union[float, torch.Tensor] = 1.0
    anchor: Optional[torch.Tensor] = None  # (B,1,H,W) the layers' value the output came from (settings.hold)
    edges: Optional[torch.Tensor] = None  # (B,1,1,1) bool: the edge steps acted on this frame (settings.hold)


class StreamFrame:
    """The stream hooks of :meth:`DepthRestorer._run` for one frame: the previous frame into the observation and
    the initial stage, this frame kept for the next (:attr:`kept`)."""

    def __init__(self, settings: StreamConfig, state: Optional[StreamState], index: int = 0,
                 singular: Optional[SingularConfig] = None):
        self.settings, self.state, self.index = settings, state, index
        self.singular = singular  # the model's singular test's settings (None: no test): the support rule's
        self.kept: Optional[StreamState] = None
        self.valid: Optional[torch.Tensor] = None
        self.stats: dict = {}  # the frame's shares: floats, or 0-d tensors read on the host only by stat_values()
        self.static: Optional[torch.Tensor] = None
        self.departed: Optional[torch.Tensor] = None  # this frame's held-out departures (observe), in depth units
        self.fresh: Optional[torch.Tensor] = None  # changed, or a static run younger than max_frames (observe)
        self.warm = False  # this frame has the previous one's prior (observe found state on a denoising task)
        self.layers_x: Optional[torch.Tensor] = None  # the layers' value, before the post-steps (post)
        self.steady: Optional[torch.Tensor] = None  # the pixels whose previous output is held (post)
        self.unit: Optional[torch.Tensor] = None  # the bounded noise unit of the runs (observe), normalised

    def stat_values(self) -> dict:
        """The frame's shares (``info["stream"]``) as floats, read from the device at once: a stream step leaves its
        statistics on the device unless they are asked for (``return_details``), and a GPU then waits for none of
        them."""
        lazy = [k for k, v in self.stats.items() if isinstance(v, torch.Tensor)]
        read = torch.stack([self.stats[k].detach().to(torch.float64) for k in lazy]).tolist() if lazy else []
        values = dict(zip(lazy, read))
        return {k: values.get(k, v) for k, v in self.stats.items()}

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

    def _unsupported(self, alone: torch.Tensor, y: torch.Tensor, observed: torch.Tensor,
                     grid_step: torch.Tensor) -> Optional[torch.Tensor]:
        """The measurements of this frame alone (``alone``) with fewer than ``settings.single_support`` agreeing
        8-neighbours and on no line (the model's support rule, its tolerance): the singular test will not trust them.
        A flying pixel at a mover floats alone; frame-by-frame restoration's test distrusted such pixels more often
        than the stream's, whose static neighbours see their runs' means, and the stream's trail was the longer
        (docs/measurements/issue28-stream/twenty-sixth-stop/). None: no rule (or no singular test)."""
        n = self.settings.single_support
        if n is None or self.singular is None:
            return None
        return alone & ~supported_pixels(y, observed, grid_step, replace(self.singular, support=n))

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
        evidence, mean = st.evidence.to(dt), st.mean.to(dt)
        drift = s.drift_test is not None and obs.rgb is not None and st.rgb is not None  # the drift test reads them
        test = change_test(obs.y, obs.observed, target, noise, obs.rgb, st.rgb, s,
                           shift_noise=torch.maximum(joining, SHIFT_FLOOR * floor),
                           runs=(obs.normalise(mean), (mean > 0) & (evidence > 0)) if drift else None)
        static = ~test.changed
        if test.own is not None:  # a hole has no depth to test: its own colour must not change
            static = static & ~(test.own & (obs.observed <= 0))
        runs = join_runs(obs.y, obs.observed, static, test.outlier, joining, evidence, mean,
                         st.departed.to(dt), st.age.to(dt), obs.offset, obs.scale, s)
        self.stats["outliers_in_time"] = runs.outlier.float().mean()
        self.stats["held_out"] = runs.held_out.float().mean()
        glitches = obs.glitches | runs.outlier  # one cheap pass; asking first whether any is there made a GPU wait
        # the singular gate also reads the pixels measured in this frame alone: the runs' means hide the past's
        # flying pixels, and with them a mover's fell below the gate (stages._gate)
        alone = ~runs.averaged
        obs = replace(obs, y=runs.y, observed=runs.observed, glitches=glitches, gate_region=alone,
                      untrusted=self._unsupported(alone, runs.y, runs.observed, obs.grid_step))
        self.departed = runs.departed.detach()
        self.static, self.warm, self.fresh = static, True, runs.fresh
        self.unit = joining
        obs = replace(obs, temporal=TemporalPrior(target, runs.weight, static, evidence, runs.averaged,
                                                  runs.restarted, test.seen))
        if s.reuse_matches and st.matches is not None:
            fresh = dilate(test.changed, search_radius(obs.block_matcher.settings, obs.task))
            obs = replace(obs, block_matcher=StreamMatcher(obs.block_matcher, st.matches, fresh, st.match_weights))
            self.stats["reused_matches"] = (~fresh).float().mean()
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
            # (max_frames measurements): those pixels alone (later_layers)
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
        if hold is not None and self.warm and st.anchor is not None and st.edges is not None and not training:
            anchor = obs.normalise(st.anchor.to(x))
            # only while the edge steps act, and acted on the previous frame (so on every frame since the output was
            # computed: a frame without them computes every pixel): a held output saves their work; elsewhere it
            # saves none and only freezes the pixel
            edges = _edges_on(state, x) & st.edges.to(x.device)
            if host_path(x.device) and not bool(edges.any()):  # nothing may be held: the post-steps of a cold frame
                self.stats["held"] = 0.0  # (whose edge steps skip a clean sample at once, a per-pixel mask does not)
            else:
                self.steady = edges & ~self.fresh & ((self.layers_x - anchor).abs() <= hold * self.unit)
                self.stats["held"] = self.steady.float().mean()
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
                                    anchor=None if s.hold is None else self._anchor(x, obs),
                                    edges=None if s.hold is None else _edges_on(state, x))


def _edges_on(state: RestorationState, like: torch.Tensor) -> torch.Tensor:
    """(B,1,1,1) bool: the singular gate found outliers, so the edge steps act (False without a gate's verdict)."""
    if state.clean is None:
        return torch.zeros(like.shape[0], 1, 1, 1, dtype=torch.bool, device=like.device)
    return (~state.clean).to(like.device).view(-1, 1, 1, 1)
