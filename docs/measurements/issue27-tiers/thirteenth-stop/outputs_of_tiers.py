"""Every tier's output on sensor-degraded synthetic frames (flying pixels, impulses, holes: the edge steps run), in
float32 and float64, saved to one file: run at two commits (``run_at.py``) and compared, it shows whether a kernel
change left the outputs bit for bit.

    python docs/measurements/issue27-tiers/thirteenth-stop/outputs_of_tiers.py OUT.pt
    python docs/measurements/issue27-tiers/thirteenth-stop/outputs_of_tiers.py --compare A.pt B.pt
"""
import sys

import torch


def outputs() -> dict:
    from torch_depth_sr import DepthRestorer
    from torch_depth_sr.datasets.synthetic import SyntheticScenes
    from torch_depth_sr.degradations import SensorDegradation

    torch.set_num_threads(2)
    out = {}
    for size in ((120, 160), (240, 320), (97, 131)):
        scenes = SyntheticScenes(n=2, size=size)
        for i in range(2):
            s = SensorDegradation(seed=i)(scenes[i])
            for dtype in (torch.float32, torch.float64):
                y, rgb = s["depth"][None].to(dtype), s["rgb"][None].to(dtype)
                for tier in ("fast", "default", "best", "full"):
                    model = DepthRestorer.from_preset(tier).to(dtype)
                    with torch.no_grad():
                        out[f"{tier}/{size[0]}x{size[1]}/{i}/{dtype}"] = model(y, rgb)
    return out


def main() -> None:
    if sys.argv[1] == "--compare":
        a, b = (torch.load(p, weights_only=True) for p in sys.argv[2:4])
        same = [k for k in a if torch.equal(a[k], b[k])]
        print(f"{len(same)} of {len(a)} outputs bit for bit the same")
        for k in a:
            if k not in same:
                print(f"  differs: {k}: {int((a[k] != b[k]).sum())} pixels, max {float((a[k] - b[k]).abs().max()):.3g}")
        return
    torch.save(outputs(), sys.argv[1])


if __name__ == "__main__":
    main()
