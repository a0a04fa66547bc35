"""The one loader of the compiled CPU kernels (numba): block matching, the singular test, the nonlocal terms.

Each kernel module imports numba at its top; :func:`cpu_kernel` imports it on first use and returns the
requested function, or None, so that the caller runs its torch path (same results, slower on a CPU). Without
numba, one warning is given per process, whichever kernel is asked for first. ``TORCH_DEPTH_SR_NO_NUMBA=1``
turns every kernel off, silently.

numba's parallel loops run on its ``workqueue`` threading layer unless ``NUMBA_THREADING_LAYER`` says
otherwise: its default, OpenMP, is a second OpenMP runtime beside torch's, and the idle threads of the two
spin against each other. With one busy background process on this 2-core machine a forward at 640×480 took
6.8 s with OpenMP and 5.6 s with workqueue (README, "Speed").
"""
from __future__ import annotations

import importlib
import os
import warnings
from typing import Callable, Optional, Sequence

import numpy as np
from numpy.typing import DTypeLike
import torch

from .errors import DepthSRError

__all__ = ["as_numpy", "cpu_kernel", "kernel_threads", "numba_disabled"]

_FAILED: Optional[str] = None  # why numba is unavailable, once known
_CONFIGURED = False


def numba_disabled() -> bool:
    """Whether ``TORCH_DEPTH_SR_NO_NUMBA`` turns the kernels off."""
    return os.environ.get("TORCH_DEPTH_SR_NO_NUMBA", "") not in ("", "0")


def _configure_numba() -> None:
    global _CONFIGURED
    if _CONFIGURED:
        return
    import numba

    if "NUMBA_THREADING_LAYER" not in os.environ:
        numba.config.THREADING_LAYER = "workqueue"
    _CONFIGURED = True


def cpu_kernel(module: str, name: str, required: bool = False) -> Optional[Callable]:
    """``torch_depth_sr.<module>.<name>`` (a numba-compiled function's wrapper), or None without numba.

    Args:
        module: the kernel module under ``torch_depth_sr`` (e.g. ``"singular_kernel"``).
        name: the function in it.
        required: raise :class:`~torch_depth_sr.errors.DepthSRError` instead of returning None.
    """
    global _FAILED
    if numba_disabled():
        if required:
            raise DepthSRError("the numba CPU kernels are unavailable: TORCH_DEPTH_SR_NO_NUMBA is set.")
        return None
    if _FAILED is None:
        try:
            _configure_numba()
            return getattr(importlib.import_module(f"torch_depth_sr.{module}"), name)
        except ImportError as exc:  # numba missing, or broken for this numpy/python
            _FAILED = f"numba could not be imported ({exc})"
            if not required:
                warnings.warn(f"torch_depth_sr: {_FAILED}; the CPU kernels (block matching, singular test, "
                              "nonlocal terms) fall back to the torch path (same results, several times slower). "
                              "`pip install numba` restores the fast path.", RuntimeWarning, stacklevel=3)
    if required:
        raise DepthSRError(f"the numba CPU kernels are unavailable: {_FAILED}. Use backend='auto' or 'torch'.")
    return None


def kernel_threads() -> int:
    """Set numba's parallel loops to torch's thread count (``torch.set_num_threads``, capped at numba's) and
    return it; the kernels run a serial loop on the calling thread when it is 1."""
    import numba

    n = max(1, min(torch.get_num_threads(), numba.config.NUMBA_NUM_THREADS))
    numba.set_num_threads(n)
    return n


def as_numpy(t: torch.Tensor, shape: Sequence[int], dtype: DTypeLike) -> np.ndarray:
    """A C-contiguous numpy array of a CPU tensor, reshaped and cast (no copy when nothing needs to change)."""
    return np.ascontiguousarray(t.detach().reshape(shape).numpy(), dtype=dtype)
