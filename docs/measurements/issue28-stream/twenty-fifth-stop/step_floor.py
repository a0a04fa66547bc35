"""What a stream step on moving sensor input would cost if whole parts of it cost nothing: the floor that faster
or mask-sparse versions of those parts could reach, against the target of 0.6 of a cold frame.

Each variant removes parts of the stream step only (the cold frames run the shipped model) and times steps 10-19 of
one of the stream track's evaluated sequences against cold frames of the same model on the same frames (wall clock,
medians), and the stream steps' post-steps (means over the same steps). The outputs of a variant are not a
restoration anyone should use; only the times are read.

    OMP_NUM_THREADS=2 python docs/measurements/issue28-stream/twenty-fifth-stop/step_floor.py \
        --sequence static-2movers --size 480x640

Variants: ``shipped``; ``no-later`` (the later layers, on crops around the fresh pixels, skipped); ``no-later-gated``
(skipped, but the singular gate's verdict set as the later layers give it on this input: flying pixels at the movers
switch the edge steps on, so the edge post-steps still run at every pixel not held: mask-sparse later layers at zero
cost); ``no-later-refiner`` (``no-later-gated`` and the refiner, which runs on the whole frame, skipped). A variant
that skipped every post-step was dropped: its outputs changed the next frames' work (the step took as long as with the
edge steps), so it measured no floor.
"""
import argparse
import collections
import statistics
import time
from dataclasses import replace

import numpy as np
import torch

import torch_depth_sr.stream.frame as frame
import torch_depth_sr.stream.post_hold as post_hold
from torch_depth_sr import restore_depth
from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, make_sequence
from torch_depth_sr.post_steps import DenoiseRefineStep, EdgeRefitStep, EdgeSnapStep
from torch_depth_sr.stream import StreamRestorer, default_stream_model

VARIANTS = ("shipped", "no-later", "no-later-gated", "no-later-refiner")
SHIPPED_LATER = frame.run_later_layers
SHIPPED_POST = frame.run_post_steps
POST_TIMES: collections.defaultdict = collections.defaultdict(float)  # the stream steps' post-steps, seconds
TIMING = {"on": False}


def _time_post_steps() -> None:
    for cls in (EdgeSnapStep, EdgeRefitStep, DenoiseRefineStep):
        forward = cls.forward

        def timed(self, *a, forward=forward, name=cls.__name__):
            t0 = time.perf_counter()
            out = forward(self, *a)
            if TIMING["on"]:
                POST_TIMES[name] += time.perf_counter() - t0
            return out

        cls.forward = timed


def _skip_later(layers, state, obs, changed):
    return state


def _skip_later_gated(layers, state, obs, changed):
    """No later layer; the gate's verdict "not clean" for every sample. That is what the shipped stream finds on
    this input: with a local script, the edge steps acted on 28 % of the pixels in both, 58 % of them near an edge."""
    return replace(state, clean=torch.zeros(state.x.shape[0], 1, 1, 1, dtype=torch.bool, device=state.x.device))


def _post_without_refiner(steps, x, state, obs, initial, steady, held):
    kept = torch.nn.ModuleList([s for s in steps if not isinstance(s, DenoiseRefineStep)])
    return post_hold.run_post_steps(kept, x, state, obs, initial, steady, held)


def patch(variant: str) -> None:
    frame.run_later_layers = {"shipped": SHIPPED_LATER, "no-later": _skip_later}.get(variant, _skip_later_gated)
    frame.run_post_steps = _post_without_refiner if variant == "no-later-refiner" else SHIPPED_POST


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sequence", default="static-2movers", choices=[s.name for s in STREAM_SEQUENCES])
    p.add_argument("--size", default="480x640")
    p.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    a = p.parse_args()
    h, w = (int(t) for t in a.size.split("x"))
    seq = make_sequence(next(s for s in STREAM_SEQUENCES if s.name == a.sequence), frames=20, height=h, width=w)
    model = default_stream_model().eval()
    print(f"{a.sequence} {a.size}, steps 10-19, {torch.get_num_threads()} threads; medians in ms")
    _time_post_steps()
    names = ("EdgeSnapStep", "EdgeRefitStep", "DenoiseRefineStep")
    print(f"{'variant':18s} {'step':>7s} {'cold':>7s} {'step/cold':>9s}   step's post-steps: " + " ".join(names))
    with torch.no_grad():
        restore_depth(seq["depth"][0].astype(np.float32), seq["rgb"][0], model=model)  # warm the kernels
        for variant in a.variants:
            stream, steps, colds = StreamRestorer(model), [], []
            POST_TIMES.clear()
            for t in range(20):
                depth, rgb = seq["depth"][t].astype(np.float32), seq["rgb"][t]
                patch(variant)
                TIMING["on"] = t >= 10
                t0 = time.perf_counter()
                stream.step(depth, rgb)
                t1 = time.perf_counter()
                TIMING["on"] = False
                patch("shipped")
                if t >= 10:
                    restore_depth(depth, rgb, model=model)
                    colds.append(time.perf_counter() - t1)
                    steps.append(t1 - t0)
            s, c = 1e3 * statistics.median(steps), 1e3 * statistics.median(colds)
            post = " ".join(f"{1e3 * POST_TIMES[n] / len(steps):.1f}" for n in names)
            print(f"{variant:18s} {s:7.1f} {c:7.1f} {s / c:9.3f}   {post}", flush=True)


if __name__ == "__main__":
    main()
