"""Issue 27: seconds of one training step (forward + backward + AdamW, batch 4 of 96x96 crops, the data of
``torch-depth-sr train``) per model, interleaved, minimum over ``--repeats`` after a warm-up.

    python docs/measurements/issue27-tiers/train_step.py --threads 1 --repeats 5 \
        --models preset:default pretrained:denoise preset:fast
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from fit import build  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--models", nargs="+", required=True)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--repeats", type=int, default=5)
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    from torch_depth_sr import DepthRestorer
    from torch_depth_sr.training.datasets import CropDataset
    from torch_depth_sr.training.train import masked_loss

    ds = CropDataset(crop=96, length=64, degradation="mixed", seed=0)
    batches = [[ds[4 * i + j] for j in range(4)] for i in range(a.repeats + 1)]
    batches = [{k: torch.stack([s[k] for s in b]) for k in ("depth", "rgb", "gt", "mask")} for b in batches]
    models = {}
    for spec in a.models:
        m = build(spec)
        models[spec] = DepthRestorer(m.config, trainable=True)
        models[spec].load_state_dict(m.state_dict())
    opts = {s: torch.optim.AdamW([q for q in m.parameters() if q.requires_grad], lr=1e-3) for s, m in models.items()}
    times = {s: [] for s in models}
    for i, b in enumerate(batches):
        for s, m in models.items():
            t0 = time.perf_counter()
            loss = masked_loss(m(b["depth"], b["rgb"]), b["gt"], b["mask"])
            opts[s].zero_grad()
            loss.backward()
            opts[s].step()
            if i:
                times[s].append(time.perf_counter() - t0)
    ref = min(times[a.models[0]])
    print(f"threads {a.threads}, load {os.getloadavg()[0]:.1f}; min of {a.repeats} steps (batch 4, 96x96)")
    for s, t in times.items():
        print(f"  {s}: {min(t):.3f} s/step ({ref / min(t):.1f}x faster than {a.models[0]})")


if __name__ == "__main__":
    main()
