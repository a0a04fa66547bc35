"""Issue 28, thirty-first stop: the change test's drift test (``StreamConfig.drift_test``) at other values, and off.

``trail_lag.py`` put the trail excess at 480×640 inside the movers, on pixels the change test called static: the
movers are slanted planes sliding by a pixel or two a frame, the depth at a pixel moves by less than the depth test's
unit a frame, and the runs' means lagged the surface. The drift test (:func:`~torch_depth_sr.stream.change.drifting`)
calls a 5×5 window changed where its measurements, each clipped to ±1 noise unit of its run's mean, sum to more than
``drift_test`` times the root of their count, and where the window's colour changed by at least half the colour
test: the form shipped at this stop (``drift_test_fit*.txt``). At ``72209f8`` without the colour
gate (``zscore_*.txt``); with ``tried_drift_test.patch`` on ``e78049c`` the forms of ``clip2_*`` and
``tabletop_friendly_variants.txt``; ``drift_test_303_480x640.txt`` is a mean of departures clipped to ±4 units
against ``drift_test`` units, a local edit not kept. Variants: ``drift-off`` (None: the stream until this stop) and
``driftK`` (``drift_test = K``). Frame-by-frame restoration runs as shipped. Run like the twenty-fifth stop's
``tried_stream_parts.py`` (the same scenes, metrics and report; ``--set tuning+300``: the 15 fitting scenes that
``twenty-third-stop/dilate_by_size.py`` runs at 480×640):

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/thirty-first-stop/drift_test_tuning.py \
        --set fit --size 120x160 --variants drift-off drift3 drift4 drift5
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "twenty-fifth-stop"))
import tried_stream_parts as tsp  # noqa: E402  (its patches table and use(); it imports the twenty-fourth stop's)

from torch_depth_sr.datasets.sequences import TUNING_SEQUENCES, recipe_sequences  # noqa: E402
from torch_depth_sr.stream import StreamRestorer  # noqa: E402

SHIPPED_STREAM = tsp.tv.StreamRestorer


def stream_with(z):
    """The stream with ``StreamConfig.drift_test = z`` (None: no drift test)."""
    return lambda model: StreamRestorer(model, {"drift_test": z})


tsp.NAMED["drift-off"] = {(tsp.tv, "StreamRestorer"): stream_with(None)}
for k in (1, 1.5, 2, 3, 3.5, 4, 4.5):
    tsp.NAMED[f"drift{k}"] = {(tsp.tv, "StreamRestorer"): stream_with(float(k))}
tsp.SHIPPED[(tsp.tv, "StreamRestorer")] = SHIPPED_STREAM
tsp.tv.SETS["tuning+300"] = lambda: [*TUNING_SEQUENCES, *recipe_sequences(range(300, 304))]
tsp.tv.SETS["303"] = lambda: list(recipe_sequences([303]))

if __name__ == "__main__":
    tsp.tv.main()
