"""Train the unrolled restorer's per-layer parameters end to end (short version of `torch-depth-sr train`).

CI (seconds, synthetic scenes only, tiny model):
    python examples/train_unrolled.py --steps 2 --crop 32 --tiny
The shipped `denoise` parameters: see docs/pretrained.md.
Many processes: torchrun --nproc_per_node 2 examples/train_unrolled.py --steps 100
"""
import argparse

import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.training import TrainConfig, train


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--crop", type=int, default=96)
    p.add_argument("--batch-size", type=int, default=4)
    p.add_argument("--out", default="out/train_unrolled")
    p.add_argument("--tiny", action="store_true", help="2 layers, small search window, synthetic data only")
    a = p.parse_args()
    torch.set_num_threads(1)
    tiny = dict(num_layers=2, block_matching={"search_window": 7, "k": 4}) if a.tiny else {}
    cfg = TrainConfig(out=a.out, steps=a.steps, crop=a.crop, batch_size=a.batch_size, model=tiny,
                      use_middlebury=not a.tiny, synthetic=3 if a.tiny else 32, val_size=1 if a.tiny else 16,
                      val_every=max(1, a.steps // 4), num_workers=0 if a.tiny else 1)
    model = train(cfg)
    for i, values in enumerate(model.layer_parameters()):
        print(f"layer {i}: " + ", ".join(f"{k}={v:.3f}" for k, v in values.items()))
    restorer = DepthRestorer.load(f"{a.out}/best")  # frozen, ready for inference
    matcher = restorer.block_matcher
    print("temperature", float(matcher.temperature), "colour weight", float(matcher.color_weight))


if __name__ == "__main__":
    main()
