"""Issue 28, thirty-second stop: the temporal prior on holes the past did not measure (``unmeasured_frames``).

A static hole whose evidence is below ``fill_evidence`` (the past never measured it confidently: a stereo shadow that
stays one, say) is pulled to the previous estimate with ``weight × min(age, unmeasured_frames)``. Beside a moving
object that estimate holds where the mover was (``shadow_fill.py``, ``wrong_fills.py``). Variants ``unmeasuredK``
(``unmeasured_frames = K``; 2 shipped until this stop). Run like the twenty-fifth stop's ``tried_stream_parts.py``
(the same scenes, metrics and report):

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/thirty-second-stop/unmeasured_tuning.py \
        --set fit --size 120x160 --variants unmeasured0 unmeasured1 unmeasured2
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "twenty-fifth-stop"))
import tried_stream_parts as tsp  # noqa: E402  (its patches table and use(); it imports the twenty-fourth stop's)

from torch_depth_sr.datasets.sequences import TUNING_SEQUENCES, recipe_sequences  # noqa: E402
from torch_depth_sr.stream import StreamRestorer  # noqa: E402

SHIPPED_STREAM = tsp.tv.StreamRestorer
for k in (0, 0.5, 1, 2):
    tsp.NAMED[f"unmeasured{k}"] = {(tsp.tv, "StreamRestorer"):
                                   lambda model, k=k: StreamRestorer(model, {"unmeasured_frames": float(k)})}
tsp.SHIPPED[(tsp.tv, "StreamRestorer")] = SHIPPED_STREAM
tsp.tv.SETS["tuning+300"] = lambda: [*TUNING_SEQUENCES, *recipe_sequences(range(300, 304))]

if __name__ == "__main__":
    tsp.tv.main()
