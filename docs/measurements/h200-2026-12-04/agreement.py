"""The GPU path against the CPU path on the same frames, per tier and for a stream: outputs computed here on the CPU
(``--save DIR``), then on a GPU from the same inputs (``--compare DIR``): the largest difference, the share of pixels
within 0.01 depth units, and the RMSE of each against the ground truth.

    python docs/measurements/h200-2026-12-04/agreement.py --save .gpuref            # on the CPU
    python docs/measurements/h200-2026-12-04/agreement.py --compare .gpuref         # where CUDA is

Inputs: the speed track's synthetic frames (``speed.make_inputs``, 480x640, batch 2, σ = 5, 5 % holes); the stream
is ``gpu_report.stream_step`` for 10 frames of the fast tier (noise drawn on the CPU: the same frames on both
devices; the first run of 2026-12-04 drew it on each device, so its stream row compared different frames).
"""
import argparse
from pathlib import Path

import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.evaluation import gpu_report, speed

TIERS = ("fast", "default", "best")
STREAM_FRAMES = 10


def outputs(device: str) -> dict:
    depth, rgb, gt = (t.to(device) for t in speed.make_inputs(480, 640, 2))
    out = {"gt": gt.cpu()}
    with torch.no_grad():
        for tier in TIERS:
            out[tier] = DepthRestorer.from_preset(tier).to(device).eval()(depth, rgb).cpu()
        step = gpu_report.stream_step(DepthRestorer.from_preset("fast").to(device).eval(), depth, rgb, gt,
                                      noise_device="cpu")  # the same frames on both devices
        for _ in range(STREAM_FRAMES):
            last = step()
        out["stream-fast"] = last.cpu()
    return out


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--save")
    p.add_argument("--compare")
    a = p.parse_args()
    if a.save:
        torch.set_num_threads(2)
        Path(a.save).mkdir(parents=True, exist_ok=True)
        torch.save(outputs("cpu"), Path(a.save) / "cpu_outputs.pt")
        print("saved", Path(a.save) / "cpu_outputs.pt")
        return
    cpu = torch.load(Path(a.compare) / "cpu_outputs.pt", weights_only=True)
    gpu = outputs("cuda")
    gt = cpu["gt"]
    rmse = lambda x: float((x - gt).pow(2).mean().sqrt())  # noqa: E731
    print(f"gt equal on both devices: {torch.equal(cpu['gt'], gpu['gt'])}")
    print("| method | max abs diff | share within 0.01 | RMSE CPU | RMSE GPU |")
    print("|---|---|---|---|---|")
    for name in (*TIERS, "stream-fast"):
        d = (cpu[name] - gpu[name]).abs()
        print(f"| {name} | {float(d.max()):.4g} | {float((d <= 0.01).double().mean()):.5f} | {rmse(cpu[name]):.4f} | "
              f"{rmse(gpu[name]):.4f} |")


if __name__ == "__main__":
    main()
