"""One process of alternate_commits.sh: a `fast` stream step after 10 frames and a cold `fast` frame in turn at
HxW, ROUNDS rounds, 2 threads; prints the minima and medians as JSON. With AB_ROOT set, torch_depth_sr is imported
from that checkout (a git worktree of an earlier commit) instead of the installed one.

    AB_ROOT=/tmp/before python docs/measurements/issue27-tiers/alternate_one.py 480x640 5
"""
import os
import sys

if os.environ.get("AB_ROOT"):  # the editable install's finder would win over sys.path: drop it
    sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in type(f).__module__
                        and "editable" not in getattr(f, "__module__", "")]
    sys.path.insert(0, os.environ["AB_ROOT"])

import json  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import torch  # noqa: E402

import torch_depth_sr  # noqa: E402
from torch_depth_sr import DepthRestorer  # noqa: E402
from torch_depth_sr.evaluation.speed import make_inputs  # noqa: E402
from torch_depth_sr.stream import StreamRestorer  # noqa: E402

torch.set_num_threads(2)
h, w = map(int, sys.argv[1].split("x"))
rounds = int(sys.argv[2])
y, rgb, gt = make_inputs(h, w, 1)
model = DepthRestorer.from_preset("fast")
stream = StreamRestorer(model)
g = torch.Generator().manual_seed(1)


def frame() -> torch.Tensor:
    return torch.where(y > 0, (gt + 5 * torch.randn(y.shape, generator=g)).clamp_min(1.0), torch.zeros_like(y))


steps, colds = [], []
with torch.no_grad():
    for _ in range(10):
        stream.step(frame(), rgb)
    model(frame(), rgb)
    for _ in range(rounds):
        f = frame()
        t0 = time.perf_counter()
        stream.step(f, rgb)
        steps.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        model(f, rgb)
        colds.append(time.perf_counter() - t0)
print(json.dumps({"root": os.path.dirname(torch_depth_sr.__file__), "step": min(steps), "cold": min(colds),
                  "step_med": statistics.median(steps), "cold_med": statistics.median(colds)}))
