"""Issue 28, thirty-first stop: the change test's depth votes in a bounded noise unit (variants ``capN``).

The change test reads each pixel in units of the local spread of the measurements about the previous estimate
(``StreamState.spread``). At a mover's edge that spread is inflated by the edge itself (misplaced edges, flying
pixels), so the pixels a mover has just left are judged in a large unit and may be called static. The runs' means and
the shift test already read a unit bounded by ``join_cap`` floors; here the depth votes and the outlier test do too:
``capN`` bounds the change test's unit by N floors (a quarter of σ̂, or the quantisation step), ``capjoin`` by the
shipped ``join_cap``.

Nothing here is shipped: ``change_test`` is wrapped in this process (run at ``e78049c``, as measured). Run like the
twenty-fifth stop's ``tried_stream_parts.py`` (the same scenes, metrics and report; ``--set tuning+300`` adds seeds
300-303, the 15 fitting scenes that ``twenty-third-stop/dilate_by_size.py`` runs at 480×640):

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/thirty-first-stop/tried_capped_unit.py \
        --set tuning+300 --size 480x640 --variants shipped capjoin
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "twenty-fifth-stop"))
import tried_stream_parts as tsp  # noqa: E402  (its patches table and use(); it imports the twenty-fourth stop's)

import torch  # noqa: E402

import torch_depth_sr.stream.frame as frame  # noqa: E402
from torch_depth_sr.datasets.sequences import TUNING_SEQUENCES, recipe_sequences  # noqa: E402

_OBSERVE = frame.StreamFrame.observe
_CHANGE_TEST = frame.change_test
_SEEN: dict = {}  # the observation the wrapped change test reads its floor from


def observe(self, obs):
    _SEEN["obs"] = obs
    return _OBSERVE(self, obs)


def capped_test(floors):
    def change_test(y, observed, previous, noise, rgb, previous_rgb, settings, shift_noise=None):
        obs = _SEEN["obs"]
        floor = torch.maximum(0.25 * obs.noise, obs.grid_step).to(y.dtype).view(-1, 1, 1, 1)
        cap = settings.join_cap if floors is None else floors
        return _CHANGE_TEST(y, observed, previous, torch.minimum(noise, cap * floor), rgb, previous_rgb, settings,
                            shift_noise=shift_noise)

    return change_test


tsp.NAMED["capjoin"] = {(frame.StreamFrame, "observe"): observe, (frame, "change_test"): capped_test(None)}
for n in (8, 16, 32):
    tsp.NAMED[f"cap{n}"] = {(frame.StreamFrame, "observe"): observe, (frame, "change_test"): capped_test(n)}
tsp.SHIPPED[(frame.StreamFrame, "observe")] = _OBSERVE
tsp.SHIPPED[(frame, "change_test")] = _CHANGE_TEST
tsp.tv.SETS["tuning+300"] = lambda: [*TUNING_SEQUENCES, *recipe_sequences(range(300, 304))]
tsp.tv.SETS["303"] = lambda: list(recipe_sequences([303]))

if __name__ == "__main__":
    tsp.tv.main()
