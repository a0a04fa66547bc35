"""Eighteenth stop: x⁰'s α⁰ by ``nonlocal_terms`` (before: α and the value statistics) and by ``nonlocal_gradient``
(after: α alone), in turn on the same input, and whether they agree bit for bit.

    python alpha_kernel_time.py [--size 480x640] [--rounds 9] [--threads 2]

The input is the speed track's scene (``evaluation.speed.make_inputs``) normalised as the model does, matched as
``denoise-fast``'s x⁰ is (7×7 window, 10 matches); the medians of the rounds.
"""
import argparse
import statistics
import time

import torch

from torch_depth_sr.evaluation.speed import make_inputs
from torch_depth_sr.nonlocal_prior import nonlocal_gradient, nonlocal_terms
from torch_depth_sr.observation import observe
from torch_depth_sr.operators import Identity, grad
from torch_depth_sr.stream import default_stream_model


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--size", default="480x640")
    p.add_argument("--rounds", type=int, default=9)
    p.add_argument("--threads", type=int, default=2)
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    h, w = map(int, a.size.split("x"))
    y, rgb, _ = make_inputs(h, w, 1)
    model = default_stream_model()
    with torch.no_grad():
        obs = observe(y, (y > 0).to(y.dtype), rgb, Identity(), None, False, model.block_matcher, False)
        m = model.block_matcher(obs.y, obs, obs.observed)
        g = grad(obs.y)
        calls = {"nonlocal_terms (before)": lambda: nonlocal_terms(obs.y, g, m)[0],
                 "nonlocal_gradient (after)": lambda: nonlocal_gradient(g, m)}
        for call in calls.values():
            call()
        times: dict = {k: [] for k in calls}
        for _ in range(a.rounds):
            for k, call in calls.items():
                t0 = time.perf_counter()
                call()
                times[k].append(time.perf_counter() - t0)
        same = torch.equal(calls["nonlocal_terms (before)"](), calls["nonlocal_gradient (after)"]())
    print(f"{h}x{w}, {a.threads} threads, medians of {a.rounds} rounds: "
          + ", ".join(f"{k} {1000 * statistics.median(v):.1f} ms" for k, v in times.items())
          + f"; the same α bit for bit: {same}")


if __name__ == "__main__":
    main()
