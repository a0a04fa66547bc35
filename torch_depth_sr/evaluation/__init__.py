"""Evaluation: the degradations of the benchmark tracks (``shared/docs/benchmark.md``)."""

from torch_depth_sr import degradations as _degradations
from torch_depth_sr.degradations import *  # noqa: F401,F403  (re-exported: the benchmark's degradations)

__all__ = list(_degradations.__all__)
