"""Issue 28, twenty-sixth stop: the stream's rule for its single measurements (``StreamConfig.single_support``) at
other counts of agreeing neighbours, and off.

The trail's excess over frame-by-frame restoration lay on flying pixels at the movers that the stream's singular
test trusted and frame-by-frame's did not (twenty-fourth stop, ``trail_excess.py``). A flying pixel floats alone: few
of its 8-neighbours agree with it (the model's support rule, :func:`~torch_depth_sr.singular.supported_or_line`). The
rule: a measurement of this frame alone (not a run's mean: a changed pixel, a new run) without ``single_support``
agreeing 8-neighbours, and on no line, is not trusted (Q = 0), whatever its P and the gate say. Variants:

* ``no-single-support`` — no such rule (the stream until this stop);
* ``single-supportN`` — the rule at N = 1, 2, 3 agreeing neighbours (3 is the model's own ``SingularConfig.support``).

Frame-by-frame restoration runs as shipped. Run like the twenty-fifth stop's ``tried_stream_parts.py`` (the same
scenes, metrics and report):

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-sixth-stop/tried_support.py \
        --set fit --size 120x160 --variants no-single-support single-support1 single-support3
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "twenty-fifth-stop"))
import tried_stream_parts as tsp  # noqa: E402  (its patches table and use(); it imports the twenty-fourth stop's)

from torch_depth_sr.stream import StreamRestorer  # noqa: E402

SHIPPED_STREAM = tsp.tv.StreamRestorer


def stream_with(count):
    """The stream with ``StreamConfig.single_support = count`` (None: no rule)."""
    return lambda model: StreamRestorer(model, {"single_support": count})


tsp.NAMED["no-single-support"] = {(tsp.tv, "StreamRestorer"): stream_with(None)}
for n in (1, 2, 3):
    tsp.NAMED[f"single-support{n}"] = {(tsp.tv, "StreamRestorer"): stream_with(n)}
tsp.SHIPPED[(tsp.tv, "StreamRestorer")] = SHIPPED_STREAM

if __name__ == "__main__":
    tsp.tv.main()
