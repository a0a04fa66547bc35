"""Every numba kernel's outputs (and two small forwards), in float32/float64 with 1 and 2 threads: saved from one
version of the kernels and compared bit for bit (np.array_equal, dtype too) with another.

    git worktree add /tmp/old 046c797 && (cd /tmp/old && NUMBA_CACHE_DIR=$(mktemp -d) \
        PYTHONPATH=/tmp/old python /path/to/kernel_outputs.py save /tmp/ref.npz)
    NUMBA_CACHE_DIR=$(mktemp -d) python docs/measurements/numba-first-use/kernel_outputs.py check /tmp/ref.npz
"""
import sys
import numpy as np
import torch
from torch_depth_sr.block_matching import block_match
from torch_depth_sr.block_matching.refine import refine_matches
from torch_depth_sr.nonlocal_kernel import nonlocal_terms_cpu
from torch_depth_sr.singular_kernel import singular_rounds_cpu
from torch_depth_sr import DepthRestorer
from torch_depth_sr.evaluation.speed import make_inputs

out = {}
for threads in (1, 2):
    torch.set_num_threads(threads)
    for dt in (torch.float32, torch.float64):
        tag = f"{threads}_{str(dt)[6:]}"
        g = torch.Generator().manual_seed(1)
        d = (torch.rand(2, 1, 37, 45, generator=g, dtype=dt) * 100).round()
        rgb = torch.rand(2, 3, 37, 45, generator=g, dtype=dt)
        trust = (torch.rand(2, 1, 37, 45, generator=g) > 0.2).to(dt)
        for tr in (None, trust):
            for rg in (None, rgb):
                m = block_match(d, rg, tr, block_size=5, search_window=11, k=6, color_weight=0.7, backend="numba")
                key = f"bm_{tag}_{tr is None}_{rg is None}"
                out[key + "_d"], out[key + "_i"] = m.dist.numpy(), m.index.numpy()
                d2 = d + torch.rand(d.shape, generator=g, dtype=dt)
                r = refine_matches(d2, m, rg, tr, block_size=5, search_window=11, k=6, color_weight=0.7, reach=1)
                out[key + "_rd"], out[key + "_ri"] = r.dist.numpy(), r.index.numpy()
        gx = torch.randn(2, 2, 37, 45, generator=g, dtype=dt)
        rs = torch.rand(2, 1, 37, 45, generator=g, dtype=dt) * 5
        for ridge in (0.0, 0.3):
            for gg in (None, gx):
                for rr in (None, rs):
                    a, xb, var, off = nonlocal_terms_cpu(d, gg, m.index, m.weight.to(dt), ridge, rr)
                    key = f"nl_{tag}_{ridge}_{gg is None}_{rr is None}"
                    if a is not None:
                        out[key + "_a"] = a.numpy()
                    out[key + "_x"], out[key + "_v"], out[key + "_o"] = xb.numpy(), var.numpy(), off.numpy()
        obs = torch.rand(2, 1, 37, 45, generator=g) > 0.1
        y0 = d * obs
        q, p = singular_rounds_cpu(y0, obs, d2, m.index, m.weight.to(dt), torch.tensor([0.8, 1.5]), 0.1, 4)
        out[f"sg_{tag}_q"], out[f"sg_{tag}_p"] = q.numpy(), p.numpy()
        y, c, _ = make_inputs(48, 64, 1)
        out[f"fw_{tag}"] = DepthRestorer()(y.to(dt), c.to(dt)).numpy()
        out[f"fwfast_{tag}"] = DepthRestorer.from_preset("fast")(y.to(dt), c.to(dt)).numpy()
mode, path = sys.argv[1], sys.argv[2]
if mode == "save":
    np.savez(path, **out)
    print("saved", len(out))
else:
    ref = np.load(path)
    bad = [k for k in ref.files if not np.array_equal(ref[k], out[k], equal_nan=True) or ref[k].dtype != out[k].dtype]
    print("compared", len(ref.files), "arrays; differing:", bad or "none")
    sys.exit(1 if bad else 0)
