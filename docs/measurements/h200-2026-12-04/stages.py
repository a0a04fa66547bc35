"""Where a tier's forward spends its time on a GPU: the stage timings of ``restore_with_details(timings=True)``
(each stage between two CUDA synchronisations, median of 3 after 2 warm-up calls) per tier at 480x640, batch 1,
then one ``fast`` forward under ``torch.profiler``: kernel launches and the operators that take the most CUDA and
CPU time.

    python docs/measurements/h200-2026-12-04/stages.py      # where CUDA is
"""
import statistics

import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.evaluation import speed

TIERS = ("fast", "default", "best")


def main() -> None:
    depth, rgb, _ = (t.cuda() for t in speed.make_inputs(480, 640, 1))
    table = {}
    with torch.no_grad():
        for tier in TIERS:
            model = DepthRestorer.from_preset(tier).cuda().eval()
            for _ in range(2):
                model(depth, rgb)
            runs = [model.restore_with_details(depth, rgb, timings=True).info for _ in range(3)]
            flat = [dict(r["seconds"], rest=r["seconds"]["total"] - sum(v for k, v in r["seconds"].items()
                                                                         if k != "total")) for r in runs]
            table[tier] = {k: 1000 * statistics.median(f.get(k, 0.0) for f in flat) for k in flat[0]}
    names = list(dict.fromkeys(k for t in table.values() for k in t))
    print("| stage (ms, 480x640, batch 1) | " + " | ".join(TIERS) + " |")
    print("|---|" + "---|" * len(TIERS))
    for k in names:
        print(f"| {k} | " + " | ".join(f"{table[t].get(k, 0.0):.1f}" for t in TIERS) + " |")
    model = DepthRestorer.from_preset("fast").cuda().eval()
    with torch.no_grad():
        model(depth, rgb)
        torch.cuda.synchronize()
        with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU,
                                                torch.profiler.ProfilerActivity.CUDA]) as prof:
            model(depth, rgb)
            torch.cuda.synchronize()
    events = prof.key_averages()
    launches = sum(e.count for e in events if e.key in ("cudaLaunchKernel", "cuLaunchKernel", "cudaLaunchKernelExC"))
    print(f"\nfast, one forward: {launches} kernel launches")
    print(events.table(sort_by="cuda_time_total", row_limit=15, max_name_column_width=50))
    print(events.table(sort_by="self_cpu_time_total", row_limit=12, max_name_column_width=50))


if __name__ == "__main__":
    main()
