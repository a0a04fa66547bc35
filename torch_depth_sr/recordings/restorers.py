"""Per-sequence restorers: objects with ``.step(depth, rgb) -> restored depth`` and ``.reset()``.

:func:`~torch_depth_sr.recordings.restore_dataset` takes a *factory* (``restorer=``), a callable with no arguments
that returns such an object. It is called once per process (each worker of ``workers=N``, each ``torchrun`` rank)
and the object is ``reset()`` before every sequence, then stepped through that sequence's frames in order:

* ``depth``: the stored map as a numpy ``(H, W)`` array in native byte order (uint8/uint16/float; 0 or NaN = no
  measurement), ``rgb``: a float32 ``(3, H', W')`` tensor in [0, 1], or None for a depth-only recording;
* it returns the restored map in the input's layout, dtype and units (what ``restore_depth`` returns).

An object whose ``stateful`` attribute is False (e.g. :class:`FrameByFrame`) declares that a frame's result does not
depend on the frames before it; a resumed sequence then skips its finished frames instead of replaying them.
The factory must be picklable for ``workers > 1`` (a module-level function or class instance, not a lambda).
"""
from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any, Optional, Protocol, Union

import torch

from ..errors import UsageError

if TYPE_CHECKING:
    from ..model import DepthRestorer

__all__ = ["Restorer", "FrameByFrame", "PretrainedRestorer", "Streaming"]


class Restorer(Protocol):
    def step(self, depth: Any, rgb: Optional[torch.Tensor]) -> Any: ...

    def reset(self) -> None: ...


class FrameByFrame:
    """Each frame on its own with ``restore_depth(depth, rgb, model=model)``: no state between frames.

    Args:
        model: a :class:`~torch_depth_sr.DepthRestorer`, or None: what ``restore_depth`` runs without one, per frame
            (:func:`~torch_depth_sr.model.default_model_for`), on ``device``.
        device: where the default model runs (``model=None`` only; a model runs where it lives).
        **kwargs: passed to :func:`~torch_depth_sr.restore_depth` (``scale_factor``, ``fill``, ``noise_sigma``).
    """

    stateful = False

    def __init__(self, model: Optional["DepthRestorer"], device: Union[str, torch.device] = "cpu", **kwargs: Any):
        self.model, self.kwargs = model, kwargs
        self.device = torch.device(device) if model is None else _device_of(model)

    def reset(self) -> None:
        pass

    def step(self, depth: Any, rgb: Optional[torch.Tensor]) -> Any:
        from ..model import default_model_for, restore_depth

        if rgb is not None:
            rgb = rgb[None].to(self.device)
        model = self.model
        if model is None:
            model = default_model_for(depth, rgb, self.kwargs.get("scale_factor"), self.device)
        with torch.no_grad():
            return restore_depth(depth, rgb, model=model, **self.kwargs)


def _device_of(model: "DepthRestorer") -> torch.device:
    p = next(iter(model.parameters()), None)
    if p is None:
        p = next(iter(model.buffers()), None)
    return p.device if p is not None else torch.device("cpu")


class Streaming:
    """Each sequence as a stream: a :class:`~torch_depth_sr.StreamRestorer` of ``model`` (a frame helped by the frames
    before it; ``reset()`` before each sequence), so a resumed sequence is replayed from its first frame.

    Args:
        model: a :class:`~torch_depth_sr.DepthRestorer`.
        **kwargs: ``fill``, ``noise_sigma``, ``scale_factor`` of :meth:`~torch_depth_sr.StreamRestorer.step`.
    """

    stateful = True

    def __init__(self, model: "DepthRestorer", **kwargs: Any):
        from ..stream import StreamRestorer

        fill = kwargs.pop("fill", "all")
        self.stream = StreamRestorer(model, fill=fill)
        self.kwargs = kwargs
        self.device = _device_of(self.stream.model)

    def reset(self) -> None:
        self.stream.reset()

    def step(self, depth: Any, rgb: Optional[torch.Tensor]) -> Any:
        if rgb is not None:
            rgb = rgb[None].to(self.device)
        with torch.no_grad():
            return self.stream.step(depth, rgb, **self.kwargs)


class PretrainedRestorer:
    """Factory of :class:`FrameByFrame` restorers running ``DepthRestorer.from_pretrained(name)`` or
    ``DepthRestorer.from_preset(preset)`` on ``device`` — of :class:`Streaming` ones with ``stream=True``;
    picklable, so it can travel to worker processes. With neither name, frame by frame runs what ``restore_depth``
    runs without a model (the ``default`` tier to denoise; :func:`~torch_depth_sr.model.default_model_for`), and a
    stream :class:`~torch_depth_sr.StreamRestorer`'s default model.

    ``device="cuda"`` under ``torchrun`` means ``cuda:$LOCAL_RANK`` (one GPU per rank).
    """

    def __init__(self, name: Optional[str] = None, device: str = "cpu", stream: bool = False, *,
                 preset: Optional[str] = None, **kwargs: Any):
        self.name, self.preset, self.device, self.stream, self.kwargs = name, preset, device, stream, kwargs
        self._model = None
        self._loaded = False

    def __getstate__(self) -> dict:
        return {**self.__dict__, "_model": None, "_loaded": False}  # each process loads its own

    def load_model(self) -> Optional["DepthRestorer"]:
        """The named model (loaded once per process); without a name None frame by frame (each frame's default
        model is chosen as it comes) and :func:`~torch_depth_sr.stream.default_stream_model` for a stream.
        :class:`UsageError` for an unknown name."""
        if not self._loaded:
            from ..model import load_named_model

            device = _rank_device(self.device)
            model = load_named_model(self.preset, self.name, device)  # as `restore` runs it
            if model is None and self.stream:  # StreamRestorer's default model, on the device
                from ..stream import default_stream_model

                model = default_stream_model().to(device)
            self._model, self._loaded = model, True
        return self._model

    def __call__(self) -> "FrameByFrame | Streaming":
        model = self.load_model()
        if self.stream:
            return Streaming(model, **self.kwargs)
        return FrameByFrame(model, _rank_device(self.device), **self.kwargs)

    def __repr__(self) -> str:
        named = f"preset={self.preset!r}" if self.preset is not None else repr(self.name)
        return f"PretrainedRestorer({named}, device={self.device!r}, stream={self.stream})"


def _rank_device(device: str) -> torch.device:
    dev = torch.device(device)
    if dev.type == "cuda" and dev.index is None and "LOCAL_RANK" in os.environ:
        return torch.device("cuda", int(os.environ["LOCAL_RANK"]))
    return dev
