"""Does a code change leave a shipped model's output bit for bit as it was? Run once per checkout, then compare.

    PYTHONPATH=/work/main python docs/measurements/guidance/same_output.py denoise-guided /tmp/before.pt
    PYTHONPATH=/tmp/wt-g2 python docs/measurements/guidance/same_output.py denoise-guided /tmp/after.pt
    python docs/measurements/guidance/same_output.py --compare /tmp/before.pt /tmp/after.pt

Restores the first four validation crops (96×96, σ = 5) of each track with the shipped model ``NAME`` (or a saved
model folder, any argument with a ``/``) and saves
the outputs; ``--compare`` prints, per track, whether the two files are equal and the max abs difference.
"""
from __future__ import annotations

import sys
from typing import Optional, Sequence

import torch


def main(argv: Optional[Sequence[str]] = None) -> None:
    args = list(sys.argv[1:] if argv is None else argv)
    if args[0] == "--compare":
        a, b = torch.load(args[1]), torch.load(args[2])
        for k in a:
            print(k, tuple(a[k].shape), "equal" if torch.equal(a[k], b[k]) else "differ",
                  f"max abs difference {float((a[k] - b[k]).abs().max()):g}")
        return
    import torch_depth_sr
    from torch_depth_sr import DepthRestorer
    from torch_depth_sr.training import TrainConfig, make_datasets

    torch.set_num_threads(1)
    cfg = TrainConfig(out="unused")
    _, val_sets = make_datasets(cfg.data, crop=cfg.crop, train_length=4, val_length=4, val_scenes=cfg.val_scenes,
                                synthetic=cfg.synthetic, sigma=cfg.sigma, val_sigma=cfg.val_sigma, scale_factor=1,
                                degradation=cfg.degradation, seed=cfg.seed, use_middlebury=cfg.use_middlebury)
    model = DepthRestorer.load(args[0]) if "/" in args[0] else DepthRestorer.from_pretrained(args[0])
    outs = {}
    with torch.no_grad():
        for k, ds in val_sets.items():
            items = [ds[j] for j in range(4)]
            outs[k] = model(torch.stack([s["depth"] for s in items]), torch.stack([s["rgb"] for s in items]))
    torch.save(outs, args[1])
    print(torch_depth_sr.__file__, "->", args[1])


if __name__ == "__main__":
    main()
