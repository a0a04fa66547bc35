"""Issue 28, twenty-eighth stop: the stream's held outputs (``StreamConfig.hold``) at other thresholds on the
synthetic sets, with the tree's rule of when an output may be held. Variants ``holdV``: ``StreamConfig.hold = V``
for V in 0.1, 0.15, 0.2, 0.25, 0.5, 1, 2 (``hold-none``: no held outputs).

Frame-by-frame restoration runs as shipped. Run like the twenty-fifth stop's ``tried_stream_parts.py`` (the same
scenes, metrics and report):

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-eighth-stop/tried_hold.py \
        --set fit --size 120x160 --variants hold-none hold0.1 hold0.25 hold0.5
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "twenty-fifth-stop"))
import tried_stream_parts as tsp  # noqa: E402  (its patches table and use(); it imports the twenty-fourth stop's)

from torch_depth_sr.stream import StreamRestorer  # noqa: E402

SHIPPED_STREAM = tsp.tv.StreamRestorer


def stream_with(hold):
    """The stream with ``StreamConfig.hold = hold`` (None: nothing held)."""
    return lambda model: StreamRestorer(model, {"hold": hold})


tsp.NAMED["hold-none"] = {(tsp.tv, "StreamRestorer"): stream_with(None)}
for v in (0.1, 0.15, 0.2, 0.25, 0.5, 1.0, 2.0):
    tsp.NAMED[f"hold{v:g}"] = {(tsp.tv, "StreamRestorer"): stream_with(v)}
tsp.SHIPPED[(tsp.tv, "StreamRestorer")] = SHIPPED_STREAM

if __name__ == "__main__":
    tsp.tv.main()
