"""``torch-depth-sr train``: argument parser and command (wired into :mod:`torch_depth_sr.cli`).

Single process::

    torch-depth-sr train --out runs/denoise --steps 300

Many processes / machines (DistributedDataParallel, gloo on CPU, nccl on GPU)::

    torchrun --nproc_per_node 4 -m torch_depth_sr.training.cli --out runs/denoise --steps 300
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from typing import Optional, Sequence

from .train import TrainConfig

__all__ = ["config_from_args", "cmd_train", "cmd_train_refiner", "add_train_parser", "add_train_refiner_parser",
           "main"]


def _add_shared_arguments(p: argparse.ArgumentParser, d, out_help: str) -> None:
    """The flags ``train`` and ``train-refiner`` have alike; ``d``: the command's settings with their defaults."""
    p.add_argument("--out", default=d.out, help=out_help)
    p.add_argument("--data", default=None, help="data root holding middlebury2006 (default: $TORCH_DEPTH_SR_DATA)")
    p.add_argument("--steps", type=int, default=d.steps)
    p.add_argument("--batch-size", type=int, default=d.batch_size, help="per process")
    p.add_argument("--crop", type=int, default=d.crop)
    p.add_argument("--lr", type=float, default=d.lr)
    p.add_argument("--synthetic", type=int, default=d.synthetic, help="number of synthetic training scenes")
    p.add_argument("--val-scenes", nargs="*", default=list(d.val_scenes), help="2006 scenes held out for validation")
    p.add_argument("--val-every", type=int, default=d.val_every)
    p.add_argument("--seed", type=int, default=d.seed)
    p.add_argument("--threads", type=int, default=d.threads, help="torch threads per process")
    p.add_argument("--loss", choices=["l2", "l1"], default=d.loss)
    p.add_argument("--downsample", choices=["area", "bicubic"], default=d.downsample,
                   help="kernel that makes the low-resolution inputs of upsampling (bicubic: the gdsr protocol's)")
    p.add_argument("--no-progress", action="store_true")


def _add_arguments(p: argparse.ArgumentParser) -> None:
    d = TrainConfig()
    _add_shared_arguments(p, d, "run folder (checkpoint/, best/, last/, history.json)")
    p.add_argument("--guidance-lr", type=float, default=d.guidance_lr,
                   help="learning rate of the guidance network's weights (--model '{\"guidance\": {}}')")
    p.add_argument("--weight-decay", type=float, default=d.weight_decay)
    p.add_argument("--degradation", choices=["paper", "sensor", "mixed"], default=d.degradation)
    p.add_argument("--sigma", type=float, nargs=2, default=list(d.sigma), metavar=("MIN", "MAX"),
                   help="training noise std range (grey levels)")
    p.add_argument("--val-sigma", type=float, default=d.val_sigma)
    p.add_argument("--scale-factor", type=int, default=d.scale_factor, help=">1: train guided upsampling")
    p.add_argument("--clean-share", type=float, default=d.clean_share,
                   help="probability of a noise-free training item (σ = 0)")
    p.add_argument("--synthetic-only", action="store_true", help="no Middlebury data (e.g. CI)")
    p.add_argument("--val-size", type=int, default=d.val_size, help="validation crops per track")
    p.add_argument("--save-every", type=int, default=d.save_every)
    p.add_argument("--workers", type=int, default=d.num_workers)
    p.add_argument("--device", default=d.device)
    p.add_argument("--resume", action="store_true", help="continue from <out>/checkpoint if present")
    p.add_argument("--stop-at", type=int, default=None, help="end this run after this step (resume later)")
    p.add_argument("--init", default=None, help="start from a pretrained name or saved folder (default: defaults)")
    p.add_argument("--model", default="{}",
                   help='RestorerConfig overrides as JSON (docs/config.md), e.g. \'{"num_layers": 4}\', '
                        '\'{"block_matching": {"k": 10}}\', \'{"block_matching.k": 10}\' or the version-1 '
                        '\'{"k": 10}\'')


def config_from_args(args: argparse.Namespace) -> TrainConfig:
    return TrainConfig(out=args.out, data=args.data, steps=args.steps, batch_size=args.batch_size, crop=args.crop,
                       lr=args.lr, guidance_lr=args.guidance_lr, weight_decay=args.weight_decay, loss=args.loss,
                       degradation=args.degradation,
                       sigma=tuple(args.sigma), val_sigma=args.val_sigma, scale_factor=args.scale_factor,
                       downsample=args.downsample, clean_share=args.clean_share,
                       synthetic=args.synthetic, use_middlebury=not args.synthetic_only,
                       val_scenes=tuple(args.val_scenes), val_size=args.val_size, val_every=args.val_every,
                       save_every=args.save_every, num_workers=args.workers, threads=args.threads, seed=args.seed,
                       device=args.device, resume=args.resume, stop_at=args.stop_at, init=args.init, model=json.loads(args.model),
                       progress=not args.no_progress)


def cmd_train(args: argparse.Namespace) -> int:
    """Run training from parsed arguments; prints where the results are."""
    from .train import train

    cfg = config_from_args(args)
    train(cfg)
    import torch.distributed as dist

    if not dist.is_initialized() or dist.get_rank() == 0:
        print(f"best parameters: {cfg.out}/best  (DepthRestorer.load('{cfg.out}/best'))")
    if dist.is_initialized():
        dist.destroy_process_group()
    return 0


def add_train_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``train`` sub-command to an ``argparse`` sub-parser set."""
    p = subparsers.add_parser("train", help="learn the per-layer parameters end to end (torchrun for DDP)")
    _add_arguments(p)
    p.set_defaults(func=cmd_train)
    return p


def _add_refiner_arguments(p: argparse.ArgumentParser) -> None:
    from .refiner import RefinerConfig

    d = RefinerConfig()
    _add_shared_arguments(p, d, "run folder (best/, last/, history.json)")
    p.add_argument("--task", choices=["upsample", "denoise"], default=d.task,
                   help="upsample: gdsr degradations, the refiner runs when K != I; denoise: the paper/sensor "
                        "degradations, it runs when K = I")
    p.add_argument("--init", default=None,
                   help="the frozen model: a pretrained name (e.g. denoise-guided) or a saved folder (default: the "
                        "defaults)")
    p.add_argument("--source", choices=["middlebury2006", "gdsr"], default=d.source,
                   help="the 2006 scenes' files: the project's copy, or the guided-SR test set's versions of them")
    p.add_argument("--base", default=json.dumps(d.base),
                   help="RestorerConfig overrides of the frozen model, as JSON, as --model of train takes them "
                        "(docs/config.md; default: %(default)s)")
    p.add_argument("--factors", type=int, nargs="+", default=list(d.factors), help="task upsample")
    p.add_argument("--noises", type=float, nargs="+", default=list(d.noises),
                   help="noise σ: upsample, on a 0-255 scale of each image's range (the gdsr protocol's); denoise, "
                        "in grey levels (the paper/sensor tracks')")
    p.add_argument("--tracks", nargs="+", choices=["paper", "sensor"], default=list(d.tracks), help="task denoise")
    p.add_argument("--seeds", type=int, default=d.seeds, help="task denoise: draws per scene, track and σ")
    p.add_argument("--channels", type=int, default=d.channels)
    p.add_argument("--layers", type=int, default=d.layers)
    p.add_argument("--upscale", type=int, default=d.upscale,
                   help="the Middlebury scenes at this many times their size (3: the pixel pitch of a full-size "
                        "capture, as the upsample-b set)")
    p.add_argument("--select", choices=["rmse", "mae"], default=d.select,
                   help="the validation metric that picks best/")
    p.add_argument("--warm-start", action="store_true",
                   help="start from the refiner --init carries (same --channels and --layers), not from random "
                        "weights: fine-tune a shipped refiner")
    p.add_argument("--evaluate", nargs="+", default=None, metavar="MODEL",
                   help="train nothing: score these saved folders or pretrained names on this recipe's validation "
                        "samples (e.g. --upscale 3 for runs trained at other pitches) and write <out>/validation.json")


def cmd_train_refiner(args: argparse.Namespace) -> int:
    """``train-refiner``: the edge refiner on the frozen model's outputs (torch_depth_sr.training.refiner)."""
    from ..errors import UsageError
    from .refiner import RefinerConfig, train_refiner

    if args.task == "upsample" and args.crop % max(args.factors):
        raise UsageError(f"--crop {args.crop} must be a multiple of every factor; got --factors {args.factors}")
    # every flag is the RefinerConfig field of its name; lists become tuples, --base is JSON
    given = {f.name: getattr(args, f.name) for f in dataclasses.fields(RefinerConfig) if hasattr(args, f.name)}
    given = {k: tuple(v) if isinstance(v, list) else v for k, v in given.items()}
    cfg = RefinerConfig(**{**given, "base": json.loads(args.base), "progress": not args.no_progress})
    if args.evaluate:
        return _evaluate(cfg, args.evaluate)
    train_refiner(cfg)
    print(f"best model: {cfg.out}/best  (DepthRestorer.load('{cfg.out}/best'))")
    return 0


def _evaluate(cfg, models: list[str]) -> int:
    """``train-refiner --evaluate``: the validation table of saved models, printed and written as JSON."""
    from pathlib import Path

    from .refiner import evaluate_refiners

    rows = evaluate_refiners(cfg, models)
    print(f"{'model':<40} {'group':>6} {'mae':>8} {'rmse':>8} {'mae model':>10} {'rmse model':>11}")
    for r in rows:
        print(f"{r['model']:<40} {r['group']:>6} {r['mae']:8.4f} {r['rmse']:8.4f} {r['mae_model']:10.4f} "
              f"{r['rmse_model']:11.4f}")
    Path(cfg.out).mkdir(parents=True, exist_ok=True)
    (Path(cfg.out) / "validation.json").write_text(json.dumps(rows, indent=2))
    print(f"json: {cfg.out}/validation.json")
    return 0


def add_train_refiner_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``train-refiner`` sub-command."""
    p = subparsers.add_parser("train-refiner", help="learn the edge refiner (guided upsampling or "
                                                    "denoising) on the frozen model's outputs")
    _add_refiner_arguments(p)
    p.set_defaults(func=cmd_train_refiner)
    return p


def main(argv: Optional[Sequence[str]] = None) -> int:
    p = argparse.ArgumentParser(prog="torch-depth-sr train", description="Train the unrolled restorer.")
    _add_arguments(p)
    return cmd_train(p.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
