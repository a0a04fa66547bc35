import time, torch, sys
torch.set_num_threads(2)
from torch_depth_sr.block_matching import block_match, refine_matches
import torch_depth_sr.block_matching.refine_cpu as rc
g = torch.Generator().manual_seed(0)
h, w = 480, 640
x = torch.rand(1, 1, h, w, generator=g) * 0.2 + torch.linspace(0, 1, w).view(1, 1, 1, w)
x = torch.nn.functional.avg_pool2d(x, 5, 1, 2)
rgb = torch.rand(1, 3, h, w, generator=g)
trust = (torch.rand(1, 1, h, w, generator=g) > 0.05).float()
def t(f, n=3):
    best = 1e9
    for _ in range(n):
        s = time.perf_counter(); r = f(); best = min(best, time.perf_counter() - s)
    return best, r
for S in [int(a) for a in sys.argv[1:]]:
    e, m = t(lambda: block_match(x, rgb, trust, 3, S, 10, 400.0, 0.5))
    x2 = x + 0.01 * torch.randn(x.shape, generator=g)
    res = {}
    for mode, lim in [("masked", 99), ("old", 0)]:
        rc._MASKED_UP_TO = lim
        for lat in (0, 2):
            tt, r = t(lambda: refine_matches(x2, m, rgb, trust, 3, S, 10, 400.0, 0.5, lattice=lat))
            res[mode, lat] = (tt, r)
    msg = f"S{S}: exact {e*1e3:.0f} ms"
    for lat in (0, 2):
        a, b = res["masked", lat][1], res["old", lat][1]
        same = float((a.index == b.index).float().mean())
        dd = float((a.dist - b.dist).abs().max())
        msg += f" | lat{lat}: masked {res['masked', lat][0]*1e3:.0f} old {res['old', lat][0]*1e3:.0f} same-index {same:.6f} maxdd {dd:.2e}"
    print(msg, flush=True)
