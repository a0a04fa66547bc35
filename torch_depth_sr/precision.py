"""The arithmetic of the model's two networks, the guidance CNN and the edge refiner: float32, or bfloat16 where the
processor multiplies bfloat16 natively.

``RestorerConfig.network_precision``:

- ``"auto"`` (the default): bfloat16 for inference on a CPU with native bfloat16 dot products (Intel AMX or
  AVX512-BF16: Sapphire Rapids and later, AMD Zen 4 and later), float32 otherwise: in training (the network's
  parameters or its input need a gradient), for float64 input (asking for precision), on other processors and on
  other devices (not measured there). This is the policy of OpenVINO's CPU plugin, whose default inference
  precision is bfloat16 on such processors.
- ``"float32"``: always float32, the same numbers on every machine (the goldens, reproducible training).
- ``"bfloat16"``: always bfloat16 (``torch.autocast``), training and other devices included.

:func:`network_precision` overrides every model's setting inside a ``with`` block: the training commands run in
float32 (``with network_precision("float32")``), so that they compute what they computed before this setting existed,
on any machine, and the models they export keep ``"auto"``. Below such a block, the environment variable
``TORCH_DEPTH_SR_NETWORK_PRECISION`` overrides it for a whole process and the processes it starts (the command line's
``--network-precision``): a recording restored on several machines, some with AMX and some without, gets one
arithmetic everywhere with ``float32``.

Only the convolutions run in bfloat16 (oneDNN accumulates each sum in float32); the features going in and the step
coming out stay in the model's dtype, and everything else the model computes (block matching, the solves, the
clamps that keep every output within the measurements around it) is untouched. At 640×480 on this project's 2-core
Sapphire Rapids machine the ``best`` tier's 129k-parameter refiner takes about 0.1 s instead of 0.6 s; the held-out
``paper`` and ``sensor`` figures of the three tiers change by less than 0.03 %
(docs/measurements/issue27-tiers/history.md, "Sixteenth stop").
"""
from __future__ import annotations

import functools
import os
from contextlib import AbstractContextManager, contextmanager
from contextvars import ContextVar
from typing import Iterator, Optional

import torch
from torch import nn

__all__ = ["ENVIRONMENT_VARIABLE", "NETWORK_PRECISIONS", "native_bfloat16", "network_autocast", "network_precision",
           "precision_override", "uses_bfloat16"]

NETWORK_PRECISIONS = ("auto", "float32", "bfloat16")
ENVIRONMENT_VARIABLE = "TORCH_DEPTH_SR_NETWORK_PRECISION"
_OVERRIDE: ContextVar[Optional[str]] = ContextVar("torch_depth_sr_network_precision", default=None)


@contextmanager
def network_precision(precision: str) -> Iterator[None]:
    """Inside the block every network runs in ``precision`` (:data:`NETWORK_PRECISIONS`), whatever its model's
    ``network_precision`` says.

    Examples:
        >>> with network_precision("float32"):
        ...     pass
    """
    if precision not in NETWORK_PRECISIONS:
        raise ValueError(f"network_precision got {precision!r}; allowed are {', '.join(NETWORK_PRECISIONS)}.")
    token = _OVERRIDE.set(precision)
    try:
        yield
    finally:
        _OVERRIDE.reset(token)


@functools.lru_cache(maxsize=None)
def _cpu_has_native_bfloat16() -> bool:
    checks = [getattr(torch.cpu, name, None) for name in ("_is_amx_tile_supported", "_is_avx512_bf16_supported")]
    return any(bool(check()) for check in checks if check is not None)


def native_bfloat16(device: torch.device) -> bool:
    """Whether ``"auto"`` runs the networks in bfloat16 on ``device``: a CPU with AMX or AVX512-BF16."""
    return device.type == "cpu" and _cpu_has_native_bfloat16()


def uses_bfloat16(precision: str, net: nn.Module, *inputs: torch.Tensor) -> bool:
    """Whether ``net`` runs in bfloat16 on ``inputs`` under ``precision`` (:data:`NETWORK_PRECISIONS`; a
    :func:`network_precision` block overrides it, and below that :data:`ENVIRONMENT_VARIABLE`)."""
    precision = precision_override() or precision
    if precision == "bfloat16":
        return True
    if precision != "auto" or not native_bfloat16(inputs[0].device):
        return False
    if any(t.dtype == torch.float64 for t in inputs):
        return False  # float64 input asks for precision
    if torch.is_grad_enabled() and (any(t.requires_grad for t in inputs) or
                                    any(p.requires_grad for p in net.parameters())):
        return False  # training: float32, as the shipped networks were trained
    return True


def precision_override() -> Optional[str]:
    """The precision every model runs its networks in here and now (a :func:`network_precision` block, else
    :data:`ENVIRONMENT_VARIABLE`), or None: each model's own setting."""
    return _OVERRIDE.get() or _from_environment()


def _from_environment() -> Optional[str]:
    value = os.environ.get(ENVIRONMENT_VARIABLE, "")
    if value and value not in NETWORK_PRECISIONS:
        raise ValueError(f"{ENVIRONMENT_VARIABLE}={value!r}; allowed are {', '.join(NETWORK_PRECISIONS)} (or unset).")
    return value or None


def network_autocast(enabled: bool, device: torch.device) -> AbstractContextManager:
    """The context the network's convolutions run in: bfloat16 autocast when ``enabled``, no change otherwise."""
    return torch.autocast(device.type, dtype=torch.bfloat16, enabled=enabled)
