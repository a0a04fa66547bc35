"""Run a script with ``torch_depth_sr`` imported from another checkout (a git worktree of an earlier commit).

    python docs/measurements/issue27-tiers/run_at.py ROOT SCRIPT [ARGS...]
    python docs/measurements/issue27-tiers/run_at.py ROOT --warmup

The editable install's import finder takes precedence over ``sys.path``, so it is dropped before ROOT is put first.
``--warmup`` compiles (or loads) ROOT's float32 kernels, so that no timed call of a later run compiles them.
"""
import os
import runpy
import sys

root = sys.argv[1]
sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in type(f).__module__
                    and "editable" not in getattr(f, "__module__", "")]
sys.path.insert(0, root)
if sys.argv[2] == "--warmup":
    import torch

    from torch_depth_sr.warmup import warmup

    warmup(dtypes=(torch.float32,))
else:
    sys.argv = sys.argv[2:]
    runpy.run_path(os.path.abspath(sys.argv[0]), run_name="__main__")
