r"""The unrolled restorer: :class:`DepthRestorer` and its functional form :func:`restore_depth`.

Objective (paper eq. 2-8, restored in model.md):

.. math::
    \min_{x,e}\ \tfrac12\|Q\odot(y-Kx-e)\|^2 + \lambda\|Dx\|_1 + \eta\|Dx-\alpha\|_1 + \gamma\|e\|_1

solved by half-quadratic splitting, one :class:`~torch_depth_sr.layers.UnrolledLayer` per iteration.

A forward is a pipeline of named stages (``repr(model)`` shows them in order): the scale policy
(:func:`~torch_depth_sr.observation.observe`, which builds the degradation ``K`` from the config's ``degradation``
and the sizes of the inputs — the identity for denoising, area or bicubic downsampling by ``s`` for guided
upsampling — and with it the task), the initial stage of the task (``init[task]``), the layers, and the post-steps
of the task (``post[task]``).
"""
from __future__ import annotations

import functools
import pickle
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, NamedTuple, Optional, Sequence, Union

import torch
import torch.nn.functional as F
from torch import nn

from ._checks import check_scale_factor
from ._inputs import map_layout, parse_depth, parse_rgb, restore_layout
from .config import TRAINED_PRESETS, RestorerConfig, load_config_file, preset_config
from .errors import DepthSRError, DTypeError, ModelFileError, ShapeError
from .guidance import GuidanceNet, NoGuidance
from .initial import InitialEstimate, initial_stages
from .layers import UnrolledLayer
from .observation import Observation, observe
from .operators import degradation_operator
from .post_steps import post_steps, run_steps
from .refiner import EdgeRefiner
from .stages import BlockMatcher, SingularDetector
from .state import RestorationState

__all__ = [
    "RestorationResult",
    "DepthRestorer",
    "FILL_MODES",
    "restore_depth",
    "default_model",
    "default_model_for",
    "named_model",
    "NoiseSigma",
]


NoiseSigma = Union[float, Sequence[float], torch.Tensor, None]
"""A noise std in depth units: one float, or one per sample (``(B,)``); None = estimate it."""


class RestorationResult(NamedTuple):
    """Result of :meth:`DepthRestorer.restore_with_details` (tensors) and of :func:`restore_depth` with
    ``return_details=True`` (in the input's array type and layout).

    ``depth`` is in the input's units. ``confidence`` (float in [0,1], on the
    observation grid) is the singular-pixel test value P(x_i) at measured pixels and 0 where there
    was no measurement; ``trusted`` is the binary Q; ``outliers`` the sparse residual e in depth
    units. ``info`` holds the noise estimate, scale, CG iterations per layer and timings.
    """

    depth: Any
    confidence: torch.Tensor
    trusted: torch.Tensor
    outliers: torch.Tensor
    info: dict


class DepthRestorer(nn.Module):
    r"""Colour-guided depth restoration as an unrolled network of ``config.num_layers`` layers.

    Frozen (``trainable=False``, the default) it is the paper's algorithm as a fixed
    preprocessing stage and no parameter requires grad. Trainable, every layer's λ, η, γ, μ₁, μ₂,
    the block-matching temperature ``h`` receive gradients (the colour weight ``ρ`` only picks the matches,
    a discrete choice, so it is a fixed buffer). With ``guidance_net=True`` a small CNN,
    :class:`~torch_depth_sr.guidance.GuidanceNet` (attribute ``guidance``), makes the layers' thresholds per-pixel
    maps; it is trained with the rest and, untrained, changes nothing.

    Args:
        config: a :class:`RestorerConfig` (defaults: the tuned frozen parameters).
        trainable: whether the parameters require grad.
        **overrides: settings to change (:meth:`RestorerConfig.replace`), e.g. ``num_layers=4``,
            ``terms=("nonlocal",)``, ``block_matching={"k": 10}`` or ``edge_snap=None``.

    The stages take their settings groups (:mod:`torch_depth_sr.config`) from the config when they are built: to
    change a setting, build a new model (``DepthRestorer(model.config.replace(...))``) and load the state dict into
    it. Named configurations: :meth:`from_preset`; trained models: :meth:`from_pretrained`.

    Examples:
        >>> from torch_depth_sr.datasets.synthetic import make_scene
        >>> s = make_scene(64, 80, seed=0)
        >>> noisy = s["gt"] + 5 * torch.randn_like(s["gt"])
        >>> out = DepthRestorer()(noisy.clamp_min(1)[None], s["rgb"][None])
        >>> out.shape
        torch.Size([1, 1, 64, 80])
    """

    def __init__(self, config: Optional[RestorerConfig] = None, trainable: bool = False, **overrides):
        super().__init__()
        config = (config or RestorerConfig()).replace(**overrides)
        self.config = config
        # the singular test of x⁰ (Q⁰ and the supported pixels) when the layers run it; each layer holds its own
        self.singular_detector = SingularDetector(config.singular) if config.uses("singular") else None
        self.init = initial_stages(config, self.singular_detector)
        self.layers = nn.ModuleList(UnrolledLayer(config, i, trainable) for i in range(config.num_layers))
        # one block matcher, owning the temperature h (learns) and the colour weight ρ (a buffer); x⁰'s matches and
        # every scheduled layer's go through it. Built after the layers so that the parameters keep their order
        # (the optimiser's state in a training checkpoint is kept by position).
        self.block_matcher = BlockMatcher(config.block_matching, trainable)
        # per-pixel multipliers of the layers' thresholds (issue 14); None = the scalar model (no state-dict keys)
        self.guidance: Optional[GuidanceNet] = None
        if config.guidance is not None:
            self.guidance = GuidanceNet(config.num_layers, config.guidance.channels, config.guidance.range,
                                        config.network_precision).requires_grad_(trainable)
        # the learned, clamped correction at depth edges, for the task it was trained for (issue 14); None = no
        # state-dict keys. Its step in ``post`` holds it; the parameters keep the key ``refiner.*``.
        self.refiner: Optional[EdgeRefiner] = None
        if config.refiner is not None:
            self.refiner = EdgeRefiner(config.refiner.channels, config.refiner.layers,
                                       config.network_precision).requires_grad_(trainable)
        self.post = post_steps(config, self.refiner)
        self._register_load_state_dict_pre_hook(_rename_legacy_keys)

    @classmethod
    def from_preset(cls, name: str, trainable: bool = False, **overrides) -> "DepthRestorer":
        """The named configuration ``name`` (:data:`~torch_depth_sr.config.PRESETS`: ``'full'``, the configuration's
        defaults, frozen; ``'paper'``, ``'tv'``, ``'tv+nl'``), then ``overrides`` (:meth:`RestorerConfig.replace`).
        The speed tiers ``'fast'``, ``'default'`` and ``'best'`` (:data:`~torch_depth_sr.config.TRAINED_PRESETS`)
        carry trained parameters: they load the shipped model they name (:meth:`from_pretrained`, ``overrides`` as
        :meth:`load` takes them). Other trained models come from :meth:`from_pretrained`.

        Examples:
            >>> DepthRestorer.from_preset("fast").config.block_matching.match_layers
            ()
            >>> DepthRestorer.from_preset("paper").config.value_prior is None
            True
        """
        if name in TRAINED_PRESETS:
            return cls.from_pretrained(TRAINED_PRESETS[name], trainable=trainable, **overrides)
        return cls(preset_config(name, **overrides), trainable=trainable)

    def forward(self, depth: torch.Tensor, rgb: Optional[torch.Tensor] = None, mask: Optional[torch.Tensor] = None,
                noise_sigma: NoiseSigma = None, scale_factor: Optional[int] = None, fill: str = "all") -> torch.Tensor:
        """The restored depth of ``depth (B,1,H,W)``, a float tensor, guided by ``rgb (B,3,H,W)`` in [0,1].

        Args:
            depth: ``(B,1,H,W)`` float16/32/64 tensor, any unit; 0 or NaN = no measurement.
            rgb: ``(B,3,H,W)`` (or greyscale ``(B,1,H,W)``; batch 1 is broadcast) float tensor in [0,1], aligned with
                the output grid: ``s`` times larger than ``depth`` for guided upsampling by ``s``. None: no guide.
            mask: optional validity mask shaped like ``depth`` (nonzero = measured), combined with the 0/NaN rule.
            noise_sigma: the noise std in depth units, a float or ``(B,)``; estimated from the input when omitted.
            scale_factor: guided upsampling factor; inferred from the sizes when omitted.
            fill: ``"all"`` fills every hole; ``"trusted"`` leaves NaN where a hole's fill is not confident.

        Returns:
            ``(B,1,sH,sW)`` in ``depth``'s dtype, on its device. :meth:`restore_with_details` returns the confidence,
            trusted set, outliers and run information as well.

        numpy arrays, ``(H,W)``/``(1,H,W)`` layouts and integer dtypes are the business of :func:`restore_depth`
        (and of :class:`~torch_depth_sr.transforms.RestoreDepth` and the command line), not of the module: they
        are refused here with a message that says so.
        """
        out = self._run_tensors(depth, rgb, mask, noise_sigma, scale_factor, fill, timed=False, details=False)
        return out.depth.to(device=depth.device, dtype=depth.dtype)

    def restore_with_details(self, depth: torch.Tensor, rgb: Optional[torch.Tensor] = None,
                             mask: Optional[torch.Tensor] = None, noise_sigma: NoiseSigma = None,
                             scale_factor: Optional[int] = None, fill: str = "all", *,
                             timings: bool = False) -> "RestorationResult":
        """:meth:`forward` with the details: a :class:`RestorationResult` of tensors on ``depth``'s device.

        ``depth`` is what :meth:`forward` returns; ``confidence``, ``trusted`` and ``outliers`` are ``(B,1,H,W)`` on
        the observation grid; ``info`` holds the noise estimate, scale, CG iterations per layer and, with
        ``timings=True``, the wall time of each stage in ``info["seconds"]`` (timing synchronises CUDA around every
        stage; without it the layers make the host wait for the device only where the algorithm needs a value).

        Examples:
            >>> from torch_depth_sr.datasets.synthetic import make_scene
            >>> s = make_scene(32, 40, seed=0)
            >>> r = DepthRestorer(num_layers=2).restore_with_details(s["gt"][None] + 1, s["rgb"][None])
            >>> r.depth.shape, r.confidence.shape, len(r.info["cg_iterations"])
            (torch.Size([1, 1, 32, 40]), torch.Size([1, 1, 32, 40]), 2)
        """
        out = self._run_tensors(depth, rgb, mask, noise_sigma, scale_factor, fill, timed=bool(timings))
        dev = depth.device
        return out._replace(depth=out.depth.to(device=dev, dtype=depth.dtype), confidence=out.confidence.detach().to(dev),
                            trusted=out.trusted.detach().to(dev), outliers=out.outliers.detach().to(dev))

    def _run_tensors(self, depth: torch.Tensor, rgb: Optional[torch.Tensor], mask: Optional[torch.Tensor],
                     noise_sigma: NoiseSigma, scale_factor: Optional[int], fill: str,
                     timed: bool, details: bool = True) -> "RestorationResult":
        """Check the tensors at the boundary, then :meth:`_run` (float64 input computes in float64, else float32)."""
        _check_fill(fill)
        _check_model_input(depth, rgb, mask)
        dtype = torch.float64 if depth.dtype == torch.float64 else torch.float32
        y, observed, _ = parse_depth(depth, mask, dtype)  # validates values: no inf, no negative, something measured
        return self._run(y, observed, rgb, noise_sigma, scale_factor, fill, timed=timed, integer_input=False,
                         details=details)

    def _run(self, y: torch.Tensor, observed: torch.Tensor, rgb: Any, noise_sigma: NoiseSigma,
             scale_factor: Optional[int], fill: str, timed: bool, integer_input: bool,
             stream: Any = None, details: bool = True) -> "RestorationResult":
        """The algorithm on parsed input: ``y``, ``observed`` (B,1,H,W) in the compute dtype (0 at missing).

        Returns the :class:`RestorationResult` on the model's device, depth in the compute dtype (NaN where
        ``fill="trusted"`` leaves a hole missing). ``integer_input``: the values were integers (uint16 millimetres,
        say), so their grid step is at least 1. ``stream``: the hooks of a
        :class:`~torch_depth_sr.stream.StreamRestorer` (the previous frame into the observation and the initial
        stage, this frame kept for the next); None = a frame on its own. ``details=False`` (:meth:`forward`) leaves
        ``info`` empty: its numbers are read on the host, which on a GPU would wait for the device.
        """
        stream = _NO_STREAM if stream is None else stream
        dev = self.block_matcher.log_temperature.device  # compute where the model lives; callers move the result back
        y, observed = y.to(dev), observed.to(dev)
        guide = None if rgb is None else parse_rgb(rgb, y.shape[0], y.device, y.dtype)
        K = degradation_operator(self.config.degradation, self._factor(y, guide, scale_factor))
        obs = stream.observe(observe(y, observed, guide, K, noise_sigma, integer_input, self.block_matcher, timed,
                                     policy=stream.scale_policy(y, observed, noise_sigma)))
        grad_needed = torch.is_grad_enabled() and (y.requires_grad or any(p.requires_grad for p in self.parameters()))
        t0 = _clock(timed, y.device)
        with torch.set_grad_enabled(grad_needed):
            initial = stream.initial(self.init[obs.task], obs)
            obs = replace(obs, prior=initial.prior, supported=initial.supported,
                          guidance=self._guidance(guide, initial.state.x))
            state = initial.state
            state = stream.run_layers(self.layers, state, obs)
            x = stream.post(self.post[obs.task], state.x, state, obs, initial)
        if timed:
            obs.log.timings["total"] = _clock(timed, x.device) - t0
        x = obs.denormalise(x)
        stream.keep(x, state, obs, initial)
        if fill == "trusted":
            x = _leave_unconfident_missing(x, initial.fill_confident, obs)
        info = {} if not details else {
                "noise_sigma": obs.sigma.tolist(), "scale": obs.scale.tolist(), "offset": obs.offset.tolist(),
                "implausible_pixels": obs.glitches.flatten(1).sum(1).tolist(),
                "cg_iterations": [int(n.max()) for n in obs.log.cg_iterations], "factor": K.scale,
                "seconds": dict(obs.log.timings or {})}
        return RestorationResult(x, state.confidence * obs.observed, state.q, state.e * obs.scale.view(-1, 1, 1, 1),
                                 info)

    def _guidance(self, guide: Optional[torch.Tensor], like: torch.Tensor) -> Any:
        """The guidance network with this forward's colour features, or unit multipliers without a network."""
        if self.guidance is None:
            return NoGuidance()
        return self.guidance.prepare(guide, like=like)

    def _factor(self, y: torch.Tensor, guide: Optional[torch.Tensor], scale_factor: Optional[int]) -> int:
        """The upsampling factor of the inputs, checked against the smallest input block matching allows."""
        factor = _infer_factor(y, guide, scale_factor)
        h, w = y.shape[-2:]
        bs = self.block_matcher.settings.block_size
        if min(h, w) * factor < bs:
            raise ShapeError(f"depth is {h}x{w} (output {h * factor}x{w * factor}); it must be at least "
                             f"{bs}x{bs}, the block size used by block matching.", actual=tuple(y.shape),
                             expected=f"output H, W >= {bs}")
        return factor

    # ---- parameters -------------------------------------------------------------------------
    def layer_parameters(self) -> list[dict]:
        """Each layer's positive parameter values, as floats."""
        return [layer.values() for layer in self.layers]

    def save(self, directory: Union[str, Path]) -> None:
        """Write ``config.json`` and ``state_dict.pt`` (tensors only; load with ``weights_only=True``)."""
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        (d / "config.json").write_text(self.config.to_json())
        torch.save(self.state_dict(), d / "state_dict.pt")

    @classmethod
    def load(cls, directory: Union[str, Path], trainable: bool = False,
             map_location: Union[str, torch.device] = "cpu", **overrides) -> "DepthRestorer":
        """Load what :meth:`save` wrote (never unpickles arbitrary objects).

        ``overrides``: settings that replace the stored ones (:meth:`RestorerConfig.replace`), e.g.
        ``edge_snap=None``; settings that change the parameters' shapes (``num_layers``, ``guidance``) make the state
        dict fail to load. A version-1 ``config.json`` converts on load with the defaults it was written with.

        Raises:
            ModelFileError: the folder or a file is missing, ``config.json`` is not valid JSON or has a field
                out of its domain, or ``state_dict.pt`` is not a state dict of this model; the message names the
                file (and the field).
        """
        d = Path(directory)
        if not d.is_dir():
            raise ModelFileError(d, "no such folder; DepthRestorer.load needs the folder DepthRestorer.save wrote "
                                    "(config.json and state_dict.pt).")
        config = load_config_file(d / "config.json")
        if overrides:
            config = config.replace(**overrides)
        model = cls(config, trainable=trainable)
        _load_state_file(model, d / "state_dict.pt", map_location)
        return model

    @classmethod
    def from_pretrained(cls, name: str, trainable: bool = False,
                        map_location: Union[str, torch.device] = "cpu", **overrides) -> "DepthRestorer":
        """Load parameters shipped in ``torch_depth_sr/pretrained/<name>/``; ``overrides`` as :meth:`load` (e.g.
        ``edge_snap=None, edge_refit=None``: without the edge steps).

        Names (``docs/pretrained.md`` has each one's training command and measured effect):
        ``'denoise'`` (denoise and fill, tracks ``paper`` + ``sensor``), ``'denoise-guided'`` (the same with the
        guidance network's per-pixel thresholds), ``'denoise-refined'`` (that model plus the edge refiner),
        ``'denoise-best'`` (the same with the refiner fine-tuned on near-clean noise as well: the best denoiser, the
        ``best`` speed tier), ``'denoise-default'`` and ``'denoise-fast2'`` (the other speed tiers),
        ``'denoise-fast'`` (the ``fast`` tier until 2026-12-05, the stream's model), ``'upsample'``
        (guided upsampling ×4–×16 with the edge refiner, bicubic-downsampled input),
        ``'upsample-x4-refined'`` (×4 only), ``'upsample-area'`` (noisy area-downsampled input, ×2–×16),
        ``'upsample-x4'`` (superseded). Trained on the Middlebury 2006 scenes and synthetic scenes only.

        Examples:
            >>> DepthRestorer.from_pretrained("denoise").config.num_layers  # doctest: +SKIP
            8
        """
        root = Path(__file__).resolve().parent / "pretrained"
        available = sorted(p.name for p in root.iterdir() if (p / "state_dict.pt").is_file()) if root.is_dir() else []
        if name not in available:
            raise DepthSRError(f"no pretrained parameters named {name!r}; available are {available} "
                             f"(folders of {root} holding config.json and state_dict.pt).")
        return cls.load(root / name, trainable=trainable, map_location=map_location, **overrides)


class _NoStream:
    """The stream hooks of :meth:`DepthRestorer._run` for a frame on its own: they change nothing."""

    def scale_policy(self, y: torch.Tensor, observed: torch.Tensor, noise_sigma: NoiseSigma) -> None:
        return None  # the frame's own

    def observe(self, obs: Observation) -> Observation:
        return obs

    def initial(self, init: nn.Module, obs: Observation) -> InitialEstimate:
        return init(obs)

    def run_layers(self, layers: nn.ModuleList, state: RestorationState, obs: Observation) -> RestorationState:
        for layer in layers:
            state = layer(state, obs)
        return state

    def post(self, steps: nn.ModuleList, x: torch.Tensor, state: RestorationState, obs: Observation,
             initial: InitialEstimate) -> torch.Tensor:
        return run_steps(steps, x, state, obs, initial)

    def keep(self, x: torch.Tensor, state: Any, obs: Observation, initial: InitialEstimate) -> None:
        pass


_NO_STREAM = _NoStream()

FILL_MODES = ("all", "trusted")


def _check_fill(fill) -> None:
    if not isinstance(fill, str) or fill not in FILL_MODES:
        raise ValueError(f"fill={fill!r}; allowed are {FILL_MODES}: 'all' fills every hole, 'trusted' leaves "
                         "holes whose fill is not confident as missing (0 for integer output, NaN for float).")


def _is_model_input(depth: Any, rgb: Any, mask: Any) -> bool:
    """Whether the arguments are what :meth:`DepthRestorer.forward` takes: 4-D tensors, float depth and colour."""
    def ok(t: Any, floating: bool = True) -> bool:
        return isinstance(t, torch.Tensor) and t.ndim == 4 and (t.is_floating_point() or not floating)

    return ok(depth) and (rgb is None or ok(rgb)) and (mask is None or ok(mask, floating=False))


def _check_model_input(depth: Any, rgb: Any, mask: Any) -> None:
    """Refuse what :meth:`DepthRestorer.forward` does not take, saying where it goes instead."""
    if _is_model_input(depth, rgb, mask):
        return
    for name, t in (("depth", depth), ("rgb", rgb), ("mask", mask)):
        if t is None:
            continue
        if not isinstance(t, torch.Tensor):
            raise DTypeError(f"{name} is a {type(t).__name__}; DepthRestorer takes torch tensors. Use "
                             "torch_depth_sr.restore_depth(depth, rgb, model=model) for numpy arrays.")
        if t.ndim != 4:
            raise ShapeError(f"{name} has shape {tuple(t.shape)}; DepthRestorer takes (B,C,H,W) tensors. Add the "
                             "batch/channel dims (depth[None, None]) or use torch_depth_sr.restore_depth, which "
                             "takes (H,W) and (1,H,W) as well.", actual=tuple(t.shape), expected="(B,C,H,W)")
        if name != "mask" and not t.is_floating_point():
            raise DTypeError(f"{name} has dtype {t.dtype}; DepthRestorer takes float tensors (rgb in [0,1]). Use "
                             "torch_depth_sr.restore_depth(depth, rgb, model=model) for integer depth or colour "
                             "(it returns the input's dtype).")


def _clock(timed: bool, device: torch.device) -> float:
    """The wall clock for the forward's total time, after the device's queue when timed (0 when not timed: the
    host must not wait for the device)."""
    if not timed:
        return 0.0
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return time.perf_counter()


def _leave_unconfident_missing(x: torch.Tensor, fill_confident: torch.Tensor, obs: Observation) -> torch.Tensor:
    """``fill="trusted"``: holes whose fill is not confident become NaN (0 once written to an integer dtype)."""
    missing = (obs.observed <= 0) & (fill_confident <= 0)  # (B,1,h,w)
    s = obs.K.scale  # each observation pixel covers s×s output pixels
    missing = F.interpolate(missing.to(x.dtype), scale_factor=s, mode="nearest") > 0
    return x.masked_fill(missing, float("nan"))


def _is_integer_dtype(dtype) -> bool:
    """Whether a numpy or torch dtype holds integers (their grid step, 1, floors the noise estimate)."""
    if dtype is None:
        return False
    if isinstance(dtype, torch.dtype):
        return not (dtype.is_floating_point or dtype.is_complex or dtype == torch.bool)
    import numpy as np

    return np.dtype(dtype).kind in "iu"


def _infer_factor(y: torch.Tensor, rgb: Optional[torch.Tensor], scale_factor: Optional[int]) -> int:
    scale_factor = check_scale_factor(scale_factor)
    h, w = y.shape[-2:]
    if rgb is None:
        if scale_factor not in (None, 1):
            raise ShapeError("guided upsampling (scale_factor > 1) needs the high-resolution colour image.",
                             actual=tuple(y.shape), expected=f"an rgb of size {h * scale_factor}x{w * scale_factor}")
        return 1
    hh, ww = rgb.shape[-2:]
    if scale_factor is None:
        if (hh, ww) == (h, w):
            return 1
        if hh % h == 0 and ww % w == 0 and hh // h == ww // w:
            return hh // h
        raise ShapeError(f"depth is {h}x{w} and rgb is {hh}x{ww}; allowed are equal sizes (restoration) or rgb "
                         "an integer multiple s of depth in both dims (guided upsampling by s). "
                         "Crop or resize so the sizes match.", actual=tuple(rgb.shape),
                         expected=f"rgb {h}x{w} or an integer multiple s of it")
    s = scale_factor
    if (hh, ww) != (h * s, w * s):
        raise ShapeError(f"scale_factor={s} needs rgb of size {h * s}x{w * s} for depth {h}x{w}; got rgb {hh}x{ww}.",
                         actual=tuple(rgb.shape), expected=f"rgb {h * s}x{w * s}")
    return s


def restore_depth(depth: Any, rgb: Any = None, mask: Any = None, *, model: Optional[DepthRestorer] = None,
                  config: Optional[RestorerConfig] = None, noise_sigma: NoiseSigma = None,
                  scale_factor: Optional[int] = None, return_details: bool = False, fill: str = "all",
                  timings: bool = False, **overrides: Any) -> Any:
    r"""Restore a depth map in one call, in the caller's array type, layout, dtype and units.

    This is where numpy arrays, ``(H,W)``/``(1,H,W)`` layouts and integer dtypes are handled (the model,
    :class:`DepthRestorer`, works on ``(B,1,H,W)`` float tensors only).

    Args:
        depth: ``(B,1,H,W)``, ``(1,H,W)`` or ``(H,W)``, torch or numpy, float or uint8/uint16,
            any unit (disparity in pixels, millimetres, metres). 0 or NaN = no measurement.
        rgb: aligned colour, ``(B,3,H,W)``/``(3,H,W)`` float in [0,1] or ``H×W×3`` uint8 numpy (RGB).
            For guided upsampling it is ``s`` times larger than ``depth``.
        mask: optional validity mask shaped like ``depth`` (nonzero = measured), combined with the
            0/NaN rule.
        model: the :class:`DepthRestorer` to run (e.g. ``DepthRestorer.from_preset("fast")``). By default, the
            ``default`` speed tier (``DepthRestorer.from_preset("default")``, a trained denoiser) when ``depth`` and
            ``rgb`` are the same size, and the frozen configuration's defaults (``DepthRestorer()``, preset
            ``"full"``) for guided upsampling; with ``config`` or ``**overrides`` (which change single fields),
            ``DepthRestorer(config, **overrides)``.
        config: a :class:`RestorerConfig`; only without ``model``.
        noise_sigma: the noise std in depth units; estimated from the input when omitted.
        scale_factor: guided upsampling factor; inferred from the sizes when omitted.
        return_details: return a :class:`RestorationResult` with the confidence and outlier maps.
        fill: ``"all"`` (default) fills every hole. ``"trusted"`` leaves as missing the holes whose fill is
            not confident (a hole at a depth gap whose side the colour does not make clear, or one too far
            from any measurement): 0 in integer output, NaN in float output. Their confidence is 0 either way.
        timings: with ``return_details``, record the wall time of each stage in ``info["seconds"]``.

    Returns:
        The restored depth in the input's layout, type and units (uint16 in → uint16 out), or a
        :class:`RestorationResult` whose maps are float32 numpy for numpy input.

    Examples:
        >>> import numpy as np
        >>> d = np.full((40, 50), 1000, np.uint16); d[10:20, 10:20] = 0
        >>> out = restore_depth(d, np.zeros((40, 50, 3), np.uint8))
        >>> out.dtype, int(out.min()), int(out.max())
        (dtype('uint16'), 1000, 1000)
    """
    if model is None and (config is not None or overrides):
        model = DepthRestorer(config, **overrides)
    elif model is not None and (config is not None or overrides):
        raise DepthSRError(f"restore_depth got a model and {'config' if config is not None else sorted(overrides)}; "
                           "pass either a model or the settings to build one (DepthRestorer(config, **overrides)).")
    _check_fill(fill)
    dtype = depth.dtype if isinstance(depth, torch.Tensor) and depth.dtype == torch.float64 else torch.float32
    y, observed, layout = parse_depth(depth, mask, dtype)
    if model is None:  # the colour parsed once here: the model's own parse of a (B,3,H,W) float tensor only checks it
        rgb = None if rgb is None else parse_rgb(rgb, y.shape[0], y.device, y.dtype)
        model = _default_model(y, rgb, scale_factor)
    out = model._run(y, observed, rgb, noise_sigma, scale_factor, fill, timed=bool(timings) and return_details,
                     integer_input=_is_integer_dtype(layout.dtype))
    x = restore_layout(out.depth, layout)  # NaN (fill="trusted") becomes 0 in an integer dtype
    if not return_details:
        return x
    return out._replace(depth=x, **{k: map_layout(getattr(out, k), layout)
                                    for k in ("confidence", "trusted", "outliers")})


def _default_model(y: torch.Tensor, guide: Optional[torch.Tensor], scale_factor: Optional[int]) -> DepthRestorer:
    """What :func:`restore_depth` runs on the parsed depth ``y (B,1,H,W)`` and colour ``guide (B,3,H',W')`` without a
    model or settings: the ``default`` speed tier, a denoiser trained for K = I, or the frozen defaults for guided
    upsampling (factor > 1, as the model infers it), which that tier was not trained for."""
    return _shipped_default(_infer_factor(y, guide, scale_factor) > 1, str(y.device))


def default_model(upsampling: bool = False, device: Union[str, torch.device] = "cpu") -> DepthRestorer:
    """The model :func:`restore_depth` runs when it is given none, on ``device``: the ``default`` speed tier
    (``DepthRestorer.from_preset("default")``, a trained denoiser), or for guided upsampling (``upsampling``) the
    frozen defaults (``DepthRestorer()``, preset ``"full"``), which that tier was not trained for. The CLI's
    ``restore`` and :class:`~torch_depth_sr.transforms.RestoreDepth` run it when nothing names a model.

    Built once per process and device and shared: in eval mode, to be run, not trained or changed (build one with
    ``DepthRestorer.from_preset`` for that)."""
    return _shipped_default(bool(upsampling), str(torch.device(device)))


def default_model_for(depth: Any, rgb: Any = None, scale_factor: Optional[int] = None,
                      device: Union[str, torch.device] = "cpu") -> DepthRestorer:
    """:func:`default_model` for these inputs, as :func:`restore_depth` would choose it: guided upsampling when the
    colour is larger than the depth or ``scale_factor`` > 1. Reads the sizes only: ``depth`` in any layout
    ``restore_depth`` takes (its last two dimensions), ``rgb`` ``(…,3,H,W)`` or an ``H×W×3`` numpy array."""
    if rgb is None:
        return default_model(False, device)
    numpy_image = not isinstance(rgb, torch.Tensor) and len(rgb.shape) == 3 and rgb.shape[-1] == 3
    size = tuple(rgb.shape[:2]) if numpy_image else tuple(rgb.shape[-2:])
    return default_model(size != tuple(depth.shape[-2:]) or (scale_factor or 1) > 1, device)


def named_model(name: str) -> DepthRestorer:
    """The model a name gives, whichever kind it is: ``DepthRestorer.from_preset(name)`` for a named configuration or
    speed tier, else ``DepthRestorer.from_pretrained(name)`` (a shipped model)."""
    from .config import PRESETS

    if name in PRESETS or name in TRAINED_PRESETS:
        return DepthRestorer.from_preset(name)
    return DepthRestorer.from_pretrained(name)


def load_named_model(preset: Optional[str] = None, pretrained: Optional[str] = None,
                     device: Union[str, torch.device] = "cpu") -> Optional[DepthRestorer]:
    """The model a command line names, on ``device``: ``DepthRestorer.from_preset(preset)`` (a speed tier or another
    named configuration) or ``DepthRestorer.from_pretrained(pretrained)``; None when neither is given (the caller
    runs :func:`default_model`). :class:`~torch_depth_sr.errors.UsageError` for both, or for an unknown name; a
    shipped file that cannot be read stays a :class:`~torch_depth_sr.errors.ModelFileError`."""
    from .errors import UsageError

    if preset is not None and pretrained is not None:
        raise UsageError(f"--preset {preset!r} and --pretrained {pretrained!r}: give one of them")
    if preset is None and pretrained is None:
        return None
    flag, name = ("--preset", preset) if preset is not None else ("--pretrained", pretrained)
    try:
        model = DepthRestorer.from_preset(preset) if preset is not None else DepthRestorer.from_pretrained(pretrained)
    except ModelFileError:
        raise  # shipped files that cannot be read: a failure, not a usage mistake
    except ValueError as e:
        raise UsageError(f"{flag} {name!r}: {e}") from e
    return model.to(device)


@functools.lru_cache(maxsize=8)
def _shipped_default(upsampling: bool, device: str = "cpu") -> DepthRestorer:
    """:func:`default_model`, cached: loading the trained tier from its files takes about 50 ms, a cost a
    DataLoader calling :func:`restore_depth` per frame would pay every frame."""
    model = DepthRestorer() if upsampling else DepthRestorer.from_preset("default")
    return model.eval().to(device)


_LEGACY_KEYS = {"log_temperature": "block_matcher.log_temperature",
                "log_color_weight": "block_matcher.log_color_weight"}


def _rename_legacy_keys(state: dict, prefix: str, *_: Any) -> None:
    """Load-state-dict pre-hook: a state dict saved before the block matcher owned h and ρ keeps them at the top
    (``log_temperature``, ``log_color_weight``); move them to their owner's keys (in place, as the hook must)."""
    for old, new in _LEGACY_KEYS.items():
        if prefix + old in state and prefix + new not in state:
            state[prefix + new] = state.pop(prefix + old)


_NOT_A_STATE_DICT = "not a torch_depth_sr state dict"


def _load_state_file(model: nn.Module, path: Path, map_location) -> None:
    """Read ``path`` with ``weights_only=True`` into ``model``; every failure names the file (ModelFileError)."""
    if not path.is_file():
        raise ModelFileError(path, "file not found; a saved model folder holds config.json and state_dict.pt "
                                   "(DepthRestorer.save writes both).")
    if path.stat().st_size == 0:
        raise ModelFileError(path, f"{_NOT_A_STATE_DICT}: the file is empty. Save the model again "
                                   "(DepthRestorer.save) or restore the file.")
    try:
        state = torch.load(path, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as exc:  # torch's message suggests weights_only=False: never for a state dict
        raise ModelFileError(path, f"{_NOT_A_STATE_DICT}: it holds Python objects other than tensors, which are "
                                   "not loaded (unpickling them could run arbitrary code).") from exc
    except Exception as exc:  # EOFError, RuntimeError (truncated zip), ...: torch names no single failure type
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ModelFileError(path, f"{_NOT_A_STATE_DICT}: it cannot be read as saved tensors ({first}). "
                                   "It may be truncated or of another program.") from exc
    if isinstance(state, dict):
        state = dict(state)
        _rename_legacy_keys(state, "")
    _check_state_matches(model, state, path)
    model.load_state_dict(state)


def _check_state_matches(model: nn.Module, state: Any, path: Path) -> None:
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise ModelFileError(path, f"{_NOT_A_STATE_DICT}: it holds a {type(state).__name__}, not a dict of tensors.")
    expected = model.state_dict()
    missing, unexpected = sorted(set(expected) - set(state)), sorted(set(state) - set(expected))
    wrong = sorted(k for k in set(expected) & set(state) if expected[k].shape != state[k].shape)
    if missing or unexpected or wrong:
        parts = [f"{what} {keys[:4]}{' ...' if len(keys) > 4 else ''}"
                 for what, keys in (("missing", missing), ("unexpected", unexpected), ("wrong shape", wrong)) if keys]
        raise ModelFileError(path, f"{_NOT_A_STATE_DICT} for the config.json next to it ({'; '.join(parts)}). "
                                   "config.json and state_dict.pt must come from the same DepthRestorer.save.")
