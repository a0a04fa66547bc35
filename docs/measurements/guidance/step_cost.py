"""Time and peak memory of one training step (forward + backward + AdamW), scalar vs guided model, on this CPU.

    OMP_NUM_THREADS=1 PYTHONPATH=. python docs/measurements/guidance/step_cost.py --guidance 0
    OMP_NUM_THREADS=1 PYTHONPATH=. python docs/measurements/guidance/step_cost.py --guidance 1

One process per setting (peak RSS is per process): batch 4 of 96×96 training crops (synthetic scenes, the
`mixed` degradations of `torch-depth-sr train`), 1 thread, 2 warm-up steps, then the median of `--steps` steps.
Prints one JSON line: seconds per step, the peak resident memory of the process (ru_maxrss) after the warm-up
and after the timed steps, and the peak bytes of tensors alive during one step (torch's CPU allocator profile).
"""
from __future__ import annotations

import argparse
import json
import resource
import statistics
import time

import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.training import CropDataset
from torch_depth_sr.training.train import TrainConfig, _param_groups, masked_loss


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--guidance", type=int, default=0)
    p.add_argument("--steps", type=int, default=5)
    a = p.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    ds = CropDataset(use_middlebury=False, synthetic=8, crop=96, length=64, seed=0)
    model = DepthRestorer(trainable=True, guidance={} if a.guidance else None)
    opt = torch.optim.AdamW(_param_groups(model, TrainConfig()), lr=0.03)

    def step(i: int) -> float:
        items = [ds[4 * i + j] for j in range(4)]
        depth, rgb, gt, mask = (torch.stack([s[k] for s in items]) for k in ("depth", "rgb", "gt", "mask"))
        t0 = time.perf_counter()
        loss = masked_loss(model(depth, rgb), gt, mask)
        opt.zero_grad()
        loss.backward()
        opt.step()
        return time.perf_counter() - t0

    for i in range(2):
        step(i)
    rss_warm = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    times = [step(2 + i) for i in range(a.steps)]
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU], profile_memory=True) as prof:
        step(2 + a.steps)
    peak = _peak_live_bytes(prof)
    n = sum(p.numel() for p in model.parameters() if p.requires_grad)
    print(json.dumps({"guidance_net": bool(a.guidance), "trainable_parameters": n,
                      "seconds_per_step_median": round(statistics.median(times), 3),
                      "seconds_per_step": [round(t, 3) for t in times],
                      "peak_rss_mib_after_warmup": round(rss_warm), "peak_rss_mib": round(rss),
                      "peak_live_tensor_mib_one_step": round(peak / 2 ** 20, 1)}))


def _peak_live_bytes(prof) -> int:
    """Peak of the running sum of CPU allocations and frees recorded by the profiler."""
    events = sorted((e for e in prof.events() if e.self_cpu_memory_usage != 0), key=lambda e: e.time_range.start)
    live = peak = 0
    for e in events:
        live += e.self_cpu_memory_usage
        peak = max(peak, live)
    return peak


if __name__ == "__main__":
    main()
