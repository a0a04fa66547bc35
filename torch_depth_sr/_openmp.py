"""How long torch's idle OpenMP threads spin, chosen before torch loads its OpenMP runtime.

Between two parallel torch operations, libgomp's idle threads spin for a while (``GOMP_SPINCOUNT``, 300 000 by
default) before they sleep. This library's numba kernels run on threads of their own
(:func:`~torch_depth_sr.native.run_tasks`), so a kernel that starts after a torch operation shares a core with a
spinning thread. On this project's 2-core machine a spin count of 10 000 made the ``fast`` and ``default`` tiers'
640×480 frames 13–15 % faster and a moving stream step 24 %; kornia's joint bilateral filter, torch alone, took about
the same time. Not spinning at all (``OMP_WAIT_POLICY=PASSIVE``) was about as fast for the tiers but 20–30 % slower for
kornia's filter: a sleeping thread wakes later for the next operation (``docs/measurements/openmp-wait-policy/``).

libgomp (torch's OpenMP on Linux) reads the count once, when torch loads it (``import torch``). So this module,
imported by the package before torch, sets ``GOMP_SPINCOUNT=10000`` only when torch is not loaded yet and neither
``GOMP_SPINCOUNT`` nor ``OMP_WAIT_POLICY`` is set: the command line, and programs that import ``torch_depth_sr`` before
torch. A program that imports torch first keeps its threads' spin; setting either variable chooses it.
"""
from __future__ import annotations

import os
import sys

__all__ = ["SPIN_COUNT", "SPIN_SET"]

SPIN_COUNT = "10000"
_CHOSEN = ("GOMP_SPINCOUNT", "OMP_WAIT_POLICY")


def _choose_spin() -> bool:
    if "torch" in sys.modules or any(name in os.environ for name in _CHOSEN):
        return False
    os.environ["GOMP_SPINCOUNT"] = SPIN_COUNT
    return True


SPIN_SET = _choose_spin()
"""Whether importing this package set ``GOMP_SPINCOUNT`` (False: torch was loaded first, or the environment chose)."""
