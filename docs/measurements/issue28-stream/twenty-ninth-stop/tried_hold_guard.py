"""Issue 28, twenty-ninth stop: no output held within ``R`` px of a fresh pixel (variants ``guardR``).

A held output keeps the edge steps' previous result at a steady pixel. The edge snap and refit read a window around
the pixel (radius 2 and 5 at ``denoise-fast``), so a static pixel beside a mover that moved has a window that
changed while its own layers' value did not. Its held output then keeps an edge decision made with the mover where
it was. Here a steady pixel must also lie more than ``R`` px from every fresh pixel (changed, or a young run).

Nothing here is shipped: ``StreamFrame.post`` is replaced in this process. Run like the twenty-fifth stop's
``tried_stream_parts.py`` (the same scenes, metrics and report; ``--set tuning+300`` adds the 15 fitting scenes that
``twenty-third-stop/dilate_by_size.py`` runs at 480×640):

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-ninth-stop/tried_hold_guard.py \
        --set tuning+300 --size 480x640 --variants shipped guard5
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "twenty-fifth-stop"))
import tried_stream_parts as tsp  # noqa: E402  (its patches table and use(); it imports the twenty-fourth stop's)

import torch_depth_sr.stream.frame as frame  # noqa: E402
from torch_depth_sr.datasets.sequences import TUNING_SEQUENCES, recipe_sequences  # noqa: E402
from torch_depth_sr.native import host_path  # noqa: E402
from torch_depth_sr.window_max import dilate  # noqa: E402
from torch_depth_sr.stream.post_hold import run_post_steps  # noqa: E402


def guarded_post(radius: int):
    """``StreamFrame.post`` as shipped, with no pixel held within ``radius`` px of a fresh one."""

    def post(self, steps, x, state, obs, initial):
        self.layers_x = x.detach()
        st, hold = self.state, self.settings.hold
        training = frame.torch.is_grad_enabled() and x.requires_grad
        if hold is not None and self.warm and st.anchor is not None and st.edges is not None and not training:
            anchor = obs.normalise(st.anchor.to(x))
            edges = frame._edges_on(state, x) & st.edges.to(x.device)
            if host_path(x.device) and not bool(edges.any()):
                self.stats["held"] = 0.0
            else:
                far = ~dilate(self.fresh, radius)
                self.steady = edges & far & ~self.fresh & ((self.layers_x - anchor).abs() <= hold * self.unit)
                self.stats["held"] = self.steady.float().mean()
        return run_post_steps(steps, x, state, obs, initial, self.steady,
                              None if self.steady is None else obs.temporal.target)

    return post


for r in (2, 5, 8):
    tsp.NAMED[f"guard{r}"] = {(frame.StreamFrame, "post"): guarded_post(r)}
tsp.tv.SETS["tuning+300"] = lambda: [*TUNING_SEQUENCES, *recipe_sequences(range(300, 304))]

if __name__ == "__main__":
    tsp.tv.main()
