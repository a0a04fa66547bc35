"""The one loader of the compiled CPU kernels (numba). Without numba the torch path runs, with one warning."""
from __future__ import annotations

import os
import warnings
from types import SimpleNamespace
from typing import Optional

from ..errors import DepthSRError

__all__ = ["cpu_kernels"]

_KERNELS: Optional[SimpleNamespace] = None
_FAILED: Optional[str] = None  # why the kernels are unavailable (warned once)


def cpu_kernels(required: bool = False) -> Optional[SimpleNamespace]:
    """The module of numba kernels (``cpu_exact`` + ``refine``'s), or None with one warning per process.

    ``TORCH_DEPTH_SR_NO_NUMBA=1`` disables them (the torch path runs: same results, slower on a CPU).
    With ``required`` a missing kernel is an error instead of a fallback.
    """
    global _KERNELS, _FAILED
    if _KERNELS is None and _FAILED is None:
        if os.environ.get("TORCH_DEPTH_SR_NO_NUMBA", "") not in ("", "0"):
            _FAILED = "TORCH_DEPTH_SR_NO_NUMBA is set"
        else:
            try:
                from . import cpu_exact, refine_cpu
            except ImportError as exc:  # numba missing or broken for this numpy/python
                _FAILED = f"numba could not be imported ({exc})"
            else:
                _KERNELS = SimpleNamespace(block_match_cpu_exact=cpu_exact.block_match_cpu_exact,
                                           refine_cpu=refine_cpu.refine_cpu)
        if _FAILED is not None and not required and "NO_NUMBA" not in _FAILED:
            warnings.warn(f"torch_depth_sr: {_FAILED}; block matching on the CPU falls back to the torch path "
                          "(same results, several times slower). `pip install numba` restores the fast path.",
                          RuntimeWarning, stacklevel=3)
    if _KERNELS is None and required:
        raise DepthSRError(f"the numba CPU kernels are unavailable: {_FAILED}. Use backend='auto' or 'torch'.")
    return _KERNELS
