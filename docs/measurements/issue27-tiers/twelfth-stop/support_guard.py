"""A prototype output guard against values of no surface, measured on the fitting split only (2006 scenes, near-clean
crops): after the model, a pixel whose value no trusted measurement of its (2r+1)² window comes within ``band`` of
(``k`` noise σ, at least 1.01 grey levels) takes the nearest such measurement; a window without a trusted
measurement keeps the model's value. A diagnosis for a later decision; nothing here is part of the library.

    python docs/measurements/issue27-tiers/twelfth-stop/support_guard.py [TIER] [K] [R]
"""
import sys
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "default-tier"))
from near_clean_2006 import SC, near_clean_crop, rmse  # noqa: E402

from torch_depth_sr import DepthRestorer  # noqa: E402
from torch_depth_sr._data_root import data_root  # noqa: E402
from torch_depth_sr.evaluation.bench import _samples  # noqa: E402
from torch_depth_sr.evaluation.fill_safety import bridging  # noqa: E402
from torch_depth_sr.metrics import evaluate  # noqa: E402


def guard(x, y, trusted, band, r):
    """(guarded x, moved mask): x (1,1,H,W) moved to the nearest trusted y of its window where none is within band."""
    d = 2 * r + 1
    vals = F.unfold(F.pad(y, (r,) * 4, mode="replicate"), d)  # (1, d², HW)
    ok = F.unfold(F.pad(trusted, (r,) * 4), d) > 0
    dist = torch.where(ok, (vals - x.flatten(2)).abs(), torch.full_like(vals, float("inf")))
    dmin, idx = dist.min(1, keepdim=True)
    nearest = vals.gather(1, idx)
    move = torch.isfinite(dmin) & (dmin > band)
    out = torch.where(move, nearest, x.flatten(2)).view_as(x)
    return out, move.view_as(x)


def run(model, depth, rgb, k, r):
    res = model.restore_with_details(depth, rgb)
    x = res.depth
    trusted = res.trusted * (depth > 0)
    band = max(k * float(res.info["noise_sigma"][0]), 1.01)
    g, moved = guard(x, depth, trusted.to(x), band, r)
    return x, g, int(moved.sum())


def main():
    torch.set_num_threads(2)
    tier = sys.argv[1] if len(sys.argv) > 1 else "default"
    k = float(sys.argv[2]) if len(sys.argv) > 2 else 3.0
    r = int(sys.argv[3]) if len(sys.argv) > 3 else 2
    model = DepthRestorer.from_preset(tier)
    print(f"# tier {tier}, band {k} noise sigma (>= 1.01 levels), window {2 * r + 1}x{2 * r + 1}")
    for sig in (0.3, 0.5):
        ratios = {"model": [], "guarded": []}
        for sc in SC:
            depth, rgb, m, noisy = near_clean_crop(sc, sig)
            x, g, n = run(model, torch.from_numpy(noisy)[None, None],
                          torch.from_numpy(rgb).permute(2, 0, 1)[None].float() / 255, k, r)
            base = rmse(noisy, depth, m)
            ratios["model"].append(rmse(x[0, 0].numpy(), depth, m) / base)
            ratios["guarded"].append(rmse(g[0, 0].numpy(), depth, m) / base)
            if sc in ("Baby1", "Baby3"):
                print(f"near-clean sigma {sig} {sc}: model {ratios['model'][-1]:.3f}  guarded {ratios['guarded'][-1]:.3f}"
                      f"  moved {n} px")
        for a, v in ratios.items():
            print(f"near-clean sigma {sig} {a:8s}: worse on {sum(q >= 1 for q in v)}/11, mean ratio {np.mean(v):.3f}, "
                  f"max {max(v):.3f}")
    for track in ("paper", "sensor"):
        acc = {"model": [], "guarded": []}
        for rec, s in _samples(track, data_root(), SC, None):
            x, g, n = run(model, s["depth"][None], s["rgb"][None], k, r)
            for a, p in (("model", x), ("guarded", g)):
                mt = evaluate(p[0], s)
                row = [mt["rmse"], mt["mae"]]
                if track == "sensor":
                    b = bridging(p[0, 0].numpy().astype(np.float64), s)
                    row += [b["bridge"], b["edge_off"]]
                acc[a].append(row)
            print(f"  {track} {rec.name:8s} moved {n:6d} px; model {np.round(acc['model'][-1], 4).tolist()} "
                  f"guarded {np.round(acc['guarded'][-1], 4).tolist()}", flush=True)
        for a, v in acc.items():
            mean = np.nanmean(np.array(v, dtype=float), 0)
            names = ["RMSE", "MAE", "bridge", "edge_off"][:len(mean)]
            print(f"{track} 2006 mean {a:8s}: " + ", ".join(f"{nm} {x:.4f}" for nm, x in zip(names, mean)))


if __name__ == "__main__":
    main()
