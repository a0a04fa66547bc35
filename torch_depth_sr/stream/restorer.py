""":class:`StreamRestorer`: a depth video restored frame by frame with state carried from one frame to the next.

Each frame runs the model's :meth:`~torch_depth_sr.DepthRestorer._run` with the hooks of
:class:`~torch_depth_sr.stream.frame.StreamFrame` (the change test, the runs' means, the temporal prior, reused
matches, the later layers on crops, held outputs) and keeps what it leaves for the next
(:class:`~torch_depth_sr.stream.frame.StreamState`). :func:`with_stream` gives the model the stream's temporal prior
term, sharing its parameters. ``docs/stream.md`` has the measurements.
"""
from __future__ import annotations

import copy
from dataclasses import fields
from typing import Any, NamedTuple, Optional, Union

import torch
from torch import nn

from .._inputs import map_layout, parse_depth, restore_layout
from ..config import SingularConfig, StreamConfig
from ..model import DepthRestorer, NoiseSigma, _check_fill, _check_model_input, _is_integer_dtype
from ..terms import TemporalPriorTerm
from .frame import StreamFrame, StreamState, TemporalPrior

__all__ = ["DEFAULT_STREAM_MODEL", "StreamRestorer", "StreamResult", "StreamState", "TemporalPrior",
           "default_stream_model", "with_stream"]


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


DEFAULT_STREAM_MODEL = "denoise-fast"
"""The shipped model a stream runs without a model: the 3-layer ``denoise-fast`` (the ``fast`` tier until
2026-12-05). Its stream settings (``layers`` 1 in its config) were fitted for it, and every figure of
``docs/stream.md`` (the ``stream`` track's default ``--model``) is of it."""


def _singular_settings(model: DepthRestorer) -> Optional[SingularConfig]:
    """The settings of the model's singular test (the stream's support rule reads its tolerance and its line rule);
    None when the layers run no such test."""
    return model.config.singular if model.config.uses("singular") else None


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
                                _is_integer_dtype(layout.dtype), return_details)
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
        out, _ = self._step(y, observed, rgb, noise_sigma, None, fill, False, False, False)
        return out.depth.to(device=depth.device, dtype=depth.dtype)

    def _step(self, y, observed, rgb, noise_sigma, scale_factor, fill, timed, integer_input, details):
        """One frame through the model with the stream's hooks. ``details``: build ``info`` (its figures are read
        from the device); without them a step reads nothing from a GPU that the model does not."""
        frame = StreamFrame(self.settings, self.state, self.frames, singular=_singular_settings(self.model))
        sigma = self.noise_sigma if noise_sigma is None else noise_sigma
        out = self.model._run(y, observed, rgb, sigma, scale_factor, fill, timed=timed, integer_input=integer_input,
                              stream=frame, details=details)
        self.state = frame.kept
        if details:
            out.info["stream"] = {"frame": self.frames, **frame.stat_values()}
        self.frames += 1
        return out, frame

    def _maps(self, out, frame: StreamFrame) -> dict:
        kept = frame.kept
        conf = out.confidence if kept is None else kept.confidence.to(out.confidence)
        static = torch.zeros_like(out.trusted, dtype=torch.bool) if frame.static is None else frame.static
        evidence = torch.zeros_like(out.trusted) if kept is None else kept.evidence.to(out.trusted)
        dev = out.trusted.device
        return {"confidence": conf.to(dev), "trusted": out.trusted, "outliers": out.outliers,
                "static": static.to(dev).to(out.trusted.dtype), "evidence": evidence.to(dev)}

    def extra_repr(self) -> str:
        return ", ".join(f"{k}={v}" for k, v in self.settings.to_dict().items()) + f", fill={self.fill!r}"
