"""Runtime A/B of the numba kernels before and after they left ``numba.prange`` (same process, alternating).

The "old" kernels are those of a git commit (default: 046c797, the last with the prange kernels), extracted into
a temporary folder and imported beside the current ones; both are checked bit-identical on every call.

    NUMBA_CACHE_DIR=/tmp/nbab python docs/measurements/numba-first-use/prange_ab.py --threads 1 --what kernels
    NUMBA_CACHE_DIR=/tmp/nbab python docs/measurements/numba-first-use/prange_ab.py --threads 2 --what forward

``--what kernels``: each kernel wrapper at 320×240 (k=10, S=21), process CPU time per call (one thread) or wall
time (more); ``--what forward``: the default DepthRestorer at 320×240, the model's kernel lookups pointed at the old
or the new modules. The first run compiles both sets (about a minute of CPU).
"""
import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

p = argparse.ArgumentParser()
p.add_argument("--commit", default="046c797")
p.add_argument("--threads", type=int, default=1)
p.add_argument("--what", choices=["kernels", "forward"], default="kernels")
p.add_argument("--reps", type=int, default=7)
args = p.parse_args()

FILES = {"old_cpu_exact": "block_matching/cpu_exact", "old_refine_cpu": "block_matching/refine_cpu",
         "old_nonlocal_kernel": "nonlocal_kernel", "old_singular_kernel": "singular_kernel"}
root = subprocess.run(["git", "rev-parse", "--show-toplevel"], capture_output=True, text=True,
                      check=True).stdout.strip()
folder = os.path.join(tempfile.gettempdir(), f"torch_depth_sr_prange_{args.commit}")
os.makedirs(folder, exist_ok=True)
for mod, path in FILES.items():
    src = subprocess.run(["git", "-C", root, "show", f"{args.commit}:torch_depth_sr/{path}.py"], capture_output=True,
                         text=True, check=True).stdout
    for old, new in (("from ..native import", "from torch_depth_sr.native import"),
                     ("from .native import", "from torch_depth_sr.native import"),
                     ("from ._common import", "from torch_depth_sr.block_matching._common import"),
                     ("from .cpu_exact import", "from old_cpu_exact import")):
        src = src.replace(old, new)
    target = os.path.join(folder, mod + ".py")
    if not os.path.exists(target) or open(target).read() != src:  # numba's cache keys on the file's stamp
        with open(target, "w") as f:
            f.write(src)
sys.path.insert(0, folder)

import numba  # noqa: E402
import torch  # noqa: E402

from torch_depth_sr import native  # noqa: E402

native._configure_numba()  # the workqueue layer, as cpu_kernel sets it, before the old modules start numba threads
import old_cpu_exact, old_nonlocal_kernel, old_refine_cpu, old_singular_kernel  # noqa: E402,E401

from torch_depth_sr import nonlocal_kernel, singular_kernel  # noqa: E402
from torch_depth_sr.block_matching import cpu_exact, refine_cpu  # noqa: E402
from torch_depth_sr.evaluation.speed import make_inputs  # noqa: E402
from torch_depth_sr.operators import grad  # noqa: E402

y, rgb, _ = make_inputs(240, 320, 1)
torch.set_num_threads(args.threads)
clock = time.process_time if args.threads == 1 else time.perf_counter
unit = "CPU" if args.threads == 1 else "wall"


def timed(call):
    numba.set_num_threads(args.threads)  # for the old prange kernels (the new ones follow torch's count)
    t0 = clock()
    out = call()
    return clock() - t0, out


def report(name, ts):
    print(f"threads {args.threads} {name:<12} " + "; ".join(
        f"{k} min {min(v) * 1e3:7.1f} ms median {statistics.median(v) * 1e3:7.1f} ms ({unit})" for k, v in ts.items()),
        flush=True)


def same(a, b):
    a, b = (a if isinstance(a, tuple) else (a,)), (b if isinstance(b, tuple) else (b,))
    return all((u is None and v is None) or torch.equal(u, v) for u, v in zip(a, b))


if args.what == "kernels":
    trust, rho = (y > 0).to(y.dtype), torch.tensor([1.0])
    d, i = cpu_exact.block_match_cpu_exact(y, rgb, trust, 5, 21, 10, rho, False, None, 1)
    w, y2, obs = torch.softmax(-d, 1), y + 0.5, y > 0
    cases = {
        "block match": (lambda m: m.block_match_cpu_exact(y, rgb, trust, 5, 21, 10, rho, False, None, 1),
                        old_cpu_exact, cpu_exact),
        "re-matching": (lambda m: m.refine_cpu(y2, rgb, trust, i, 5, 21, 10, rho, False, 1, 2), old_refine_cpu,
                        refine_cpu),
        "nonlocal": (lambda m: m.nonlocal_terms_cpu(y, grad(y), i, w, 0.1, None), old_nonlocal_kernel, nonlocal_kernel),
        "singular": (lambda m: m.singular_rounds_cpu(y, obs, y2, i, w, torch.tensor([1.0]), 0.5, 5),
                     old_singular_kernel, singular_kernel),
    }
    for name, (call, old, new) in cases.items():
        assert same(timed(lambda: call(old))[1], timed(lambda: call(new))[1]), name
        ts = {"old": [], "new": []}
        for it in range(args.reps):
            for k in (("old", "new") if it % 2 else ("new", "old")):
                ts[k].append(timed(lambda: call(old if k == "old" else new))[0])
        report(name, ts)
else:
    from torch_depth_sr import DepthRestorer
    import torch_depth_sr.block_matching as bm
    import torch_depth_sr.block_matching.refine as rf
    import torch_depth_sr.nonlocal_prior as nlp
    import torch_depth_sr.singular as sg

    OLD = {"block_matching.cpu_exact": old_cpu_exact, "block_matching.refine_cpu": old_refine_cpu,
           "nonlocal_kernel": old_nonlocal_kernel, "singular_kernel": old_singular_kernel}
    mode = {"v": "new"}

    def kernel(module, name, required=False):
        f = native.cpu_kernel(module, name, required)
        return getattr(OLD[module], name) if f is not None and mode["v"] == "old" else f

    for m in (bm, rf, nlp, sg):
        m.cpu_kernel = kernel
    model = DepthRestorer()
    outs = {}
    for v in ("old", "new"):
        mode["v"] = v
        outs[v] = timed(lambda: model(y, rgb))[1]
    assert torch.equal(outs["old"], outs["new"])
    ts = {"old": [], "new": []}
    for it in range(args.reps):
        for v in (("old", "new") if it % 2 else ("new", "old")):
            mode["v"] = v
            ts[v].append(timed(lambda: model(y, rgb))[0])
    report("forward", ts)
