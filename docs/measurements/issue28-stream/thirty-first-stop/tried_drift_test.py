"""Issue 28, thirty-first stop: a drift test in the change test (variants ``driftK`` and ``driftK-wW``).

``trail_lag.py`` put the trail excess at 480×640 inside the movers, on pixels the change test calls static: a
mover is a slanted plane, and as it slides by a pixel or two per frame the depth at a pixel moves by less than the
depth test's 2 units a frame (its nearest-of-3×3 tolerance takes up a pixel of the slide). The run's mean then lags
the surface. Each measurement alone is within the noise, but a window's measurements all lie on one side of their
runs' means. Here a pixel is changed too where the window mean of ``y − m`` (``m`` the previous frame's run mean,
over the window's pixels measured now and with a run) exceeds ``K`` noise units / √n (n those pixels, at least 3):
a test of the window's mean, which a drift passes and noise does not. W: the window (default the change test's, 3).
``driftK-w5-cC``: each pixel's ``(y − m) / unit`` clipped to ±C first (C = 0: its sign alone, a sign test), so that a
flying pixel or an impulse, far from its run's mean, weighs no more than a unit.

``change_test`` is wrapped in this process; the package has had its own drift test since (``StreamConfig.drift_test``,
with a colour gate): run this at ``e78049c``, before it, or the two add up. Run like ``tried_capped_unit.py``:

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/thirty-first-stop/tried_drift_test.py \
        --set tuning+300 --size 480x640 --variants shipped drift4
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "twenty-fifth-stop"))
import tried_stream_parts as tsp  # noqa: E402  (its patches table and use(); it imports the twenty-fourth stop's)

import torch  # noqa: E402
import torch.nn.functional as F  # noqa: E402

import torch_depth_sr.stream.frame as frame  # noqa: E402
from torch_depth_sr.datasets.sequences import TUNING_SEQUENCES, recipe_sequences  # noqa: E402
from torch_depth_sr.window_max import dilate  # noqa: E402

_OBSERVE = frame.StreamFrame.observe
_CHANGE_TEST = frame.change_test
_SEEN: dict = {}  # the frame and observation the wrapped change test reads


def observe(self, obs):
    _SEEN["frame"], _SEEN["obs"] = self, obs
    return _OBSERVE(self, obs)


def _box_sum(v: torch.Tensor, window: int) -> torch.Tensor:
    return F.avg_pool2d(v.double(), window, 1, window // 2, count_include_pad=True) * window * window


def drifting(y, observed, noise, k: float, window: int, clip=None) -> torch.Tensor:
    st, obs = _SEEN["frame"].state, _SEEN["obs"]
    mean = obs.normalise(st.mean.to(y.dtype))
    both = (observed > 0) & (st.mean.to(y.device) > 0) & (st.evidence.to(y.device) > 0)
    d = (y - mean) / noise.expand_as(y)
    d = d if clip is None else (torch.sign(d) if clip == 0 else d.clamp(-clip, clip))
    d = torch.where(both, d, torch.zeros_like(y))
    n = _box_sum(both.to(y.dtype), window)
    s = _box_sum(d, window)
    return (n >= 3) & (s.abs() > k * n.clamp_min(1).sqrt())


def drift_test(k: float, window, clip=None):
    def change_test(y, observed, previous, noise, rgb, previous_rgb, settings, shift_noise=None):
        test = _CHANGE_TEST(y, observed, previous, noise, rgb, previous_rgb, settings, shift_noise=shift_noise)
        drift = dilate(drifting(y, observed, noise, k, window or settings.window, clip), settings.dilate)
        changed = test.changed | drift
        outlier = test.outlier & ~changed
        return test._replace(changed=changed, outlier=outlier)

    return change_test


for k in (2, 3, 4, 6, 8):
    for w in (None, 5):
        tsp.NAMED[f"drift{k}" + ("" if w is None else f"-w{w}")] = {
            (frame.StreamFrame, "observe"): observe, (frame, "change_test"): drift_test(k, w)}
for k in (3, 3.5, 4, 5, 6):
    for c in (0, 1):
        tsp.NAMED[f"drift{k}-w5-c{c}"] = {
            (frame.StreamFrame, "observe"): observe, (frame, "change_test"): drift_test(k, 5, c)}
tsp.SHIPPED[(frame.StreamFrame, "observe")] = _OBSERVE
tsp.SHIPPED[(frame, "change_test")] = _CHANGE_TEST
tsp.tv.SETS["tuning+300"] = lambda: [*TUNING_SEQUENCES, *recipe_sequences(range(300, 304))]
tsp.tv.SETS["303"] = lambda: list(recipe_sequences([303]))

if __name__ == "__main__":
    tsp.tv.main()
