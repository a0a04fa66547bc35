"""Recall and time of the re-matching algorithms, on the estimates the model really matches on (issue 13).

Runs the default model once with exact re-matching on the speed benchmark's input (synthetic scene, σ = 5,
~5 % holes; ``--size H W``), records the estimate, trust mask and previous matches of every re-matching layer,
then, per layer, runs each candidate algorithm on exactly those inputs and reports the share of the exact
``k`` nearest blocks it recovers (recall), the mean kept distance relative to the exact one, and its time
(median of ``--repeats``). The effect on accuracy is measured by the benchmark tracks with
``--config '{"block_matching": {"rematch": "exact"}}'`` and the default (``"refine"``, lattice 2)::

    python -m torch_depth_sr.evaluation.matching_candidates --size 480 640
"""
from __future__ import annotations

import argparse
import statistics
import time
from contextlib import contextmanager
from typing import Optional, Sequence

import torch

from ..block_matching import BlockMatches, block_match, refine_matches
from ..model import DepthRestorer
from .report import print_table
from .speed import make_inputs

__all__ = ["CANDIDATES", "recall", "main"]

# name -> how the re-matching layer finds its candidates
CANDIDATES = {
    "exact (oracle)": dict(kind="exact"),
    "previous, re-scored (= kept as they are)": dict(kind="refine", reach=0, lattice=0),
    "previous + 4 neighbours' (PatchMatch propagation)": dict(kind="refine", reach=1, lattice=0),
    "previous + lattice 2 (default)": dict(kind="refine", reach=0, lattice=2),
    "previous + lattice 3": dict(kind="refine", reach=0, lattice=3),
    "previous + 4 neighbours' + lattice 3": dict(kind="refine", reach=1, lattice=3),
    "lattice 2 alone (search_stride=2)": dict(kind="stride", stride=2),
}


def recall(found: BlockMatches, exact: BlockMatches) -> float:
    """Share of the exact k nearest blocks (per pixel) that ``found`` contains."""
    return float((exact.index.unsqueeze(2) == found.index.unsqueeze(1)).any(2).float().mean())


@contextmanager
def _recording(matcher, calls: list):
    """Record the inputs and the matches of every re-matching pass of the model's block matcher (its
    :meth:`~torch_depth_sr.stages.BlockMatcher.rematch`, which the scheduled layers call)."""
    original = matcher.rematch

    def record(x, obs, q, previous):
        m = original(x, obs, q, previous)
        calls.append(dict(x=x.detach().clone(), trust=q.detach().clone() if obs.task == "denoise" else None,
                          rgb=obs.rgb, previous=previous, exact=m))
        return m

    matcher.rematch = record
    try:
        yield
    finally:
        del matcher.rematch  # the method again


def _run(spec: dict, call: dict, kw: dict) -> BlockMatches:
    x, rgb, trust, prev = call["x"], call["rgb"], call["trust"], call["previous"]
    if spec["kind"] == "exact":
        return block_match(x, rgb, trust, **kw)
    if spec["kind"] == "stride":
        return block_match(x, rgb, trust, **kw, search_stride=spec["stride"])
    return refine_matches(x, prev, rgb, trust, **kw, reach=spec["reach"], lattice=spec["lattice"])


def main(argv: Optional[Sequence[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--size", type=int, nargs=2, default=(480, 640), metavar=("H", "W"))
    p.add_argument("--repeats", type=int, default=3)
    a = p.parse_args(argv)
    y, rgb, _ = make_inputs(*a.size, 1)
    model = DepthRestorer(block_matching={"rematch": "exact"})
    c = model.config.block_matching
    calls: list = []
    matcher = model.block_matcher
    with torch.no_grad(), _recording(matcher, calls):
        model(y, rgb)
    rows = []
    for n, call in enumerate(c for c in calls if c["previous"] is not None):
        kw = dict(block_size=c.block_size, search_window=c.search_window, k=c.k,
                  color_weight=float(matcher.color_weight), temperature=float(matcher.temperature))
        exact = call["exact"]
        for name, spec in CANDIDATES.items():
            with torch.no_grad():
                _run(spec, call, kw)  # warm-up (numba compiles on first use)
                times = []
                for _ in range(a.repeats):
                    t0 = time.perf_counter()
                    found = _run(spec, call, kw)
                    times.append(time.perf_counter() - t0)
            rows.append({"re-match": n + 1, "candidates": name, "recall": recall(found, exact),
                         "dist / exact": float(found.dist.mean() / exact.dist.mean()),
                         "seconds": statistics.median(times)})
    print_table(rows, ["re-match", "candidates", "recall", "dist / exact", "seconds"],
                f"re-matching candidates at {a.size[1]}x{a.size[0]}, {torch.get_num_threads()} thread(s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
