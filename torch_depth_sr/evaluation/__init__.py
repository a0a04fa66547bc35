"""Evaluation: the degradations of the benchmark tracks (``shared/docs/benchmark.md``)."""

from torch_depth_sr.degradations import (
    PROTOCOLS,
    PaperDegradation,
    SensorDegradation,
    edge_band,
    make_degradation,
    scene_rng,
    stable_hash,
)

__all__ = [
    "PROTOCOLS",
    "PaperDegradation",
    "SensorDegradation",
    "edge_band",
    "make_degradation",
    "scene_rng",
    "stable_hash",
]
