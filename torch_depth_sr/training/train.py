r"""End-to-end training of the unrolled restorer's parameters.

What is learned: every layer's raw (softplus) λ, η, γ, μ₁, μ₂, the log block-matching
temperature and, with ``--model '{"guidance": {}}'``, the weights of the guidance network
(at their own learning rate ``guidance_lr``) of ``DepthRestorer(trainable=True)`` — all of
``model.parameters()`` that require grad — by AdamW through all layers (block-matching indices and the binary Q
carry no gradient; the weights ω = softmax(−d/h) do). The loss is the mean squared (``l2``) or
absolute (``l1``) error on the pixels where the ground truth is known (``gt mask``).

Distributed: launched by ``torchrun --nproc_per_node N`` (``WORLD_SIZE`` > 1 in the environment)
the model is wrapped in ``DistributedDataParallel`` (backend ``gloo`` on CPU, ``nccl`` on CUDA,
``find_unused_parameters=True`` since switched-off terms leave parameters outside the graph) and
rank ``r`` takes items ``step·B·N + r·B + j`` of the stateless :class:`CropDataset`, so the ranks
see disjoint data and a resumed run sees the same data as an uninterrupted one.

Checkpoint folder ``<out>/checkpoint``: ``config.json`` + ``state_dict.pt`` (the
:meth:`DepthRestorer.save` format), ``optimizer.pt`` and ``trainer.json`` (step, history, the
training settings), all read back with ``torch.load(..., weights_only=True)``. The best
parameters by validation RMSE are exported to ``<out>/best`` in the ``DepthRestorer.load`` format.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Union

import torch
import torch.distributed as dist
from torch.utils.data import DataLoader, Dataset, Sampler

from ..config import RestorerConfig, apply_overrides
from ..model import DepthRestorer
from ..precision import network_precision
from .datasets import make_datasets


@dataclass
class TrainConfig:
    """Settings of :func:`train` (the CLI flags mirror these names)."""

    out: str = "runs/train"
    data: Optional[str] = None  # data root; default $TORCH_DEPTH_SR_DATA or ../shared/data
    steps: int = 300
    batch_size: int = 4
    crop: int = 96
    lr: float = 0.03
    # learning rate of the guidance network's weights (RestorerConfig.guidance), which start at 0 in the heads:
    # Adam moves every weight by about lr per step, and the scalars' 0.03 would saturate the multipliers at once
    guidance_lr: float = 1e-3
    weight_decay: float = 0.0
    loss: str = "l2"  # "l2" or "l1", on gt-valid pixels
    degradation: str = "mixed"  # paper | sensor | mixed
    sigma: tuple = (3.0, 8.0)
    val_sigma: float = 5.0
    scale_factor: int = 1
    downsample: str = "area"  # upsampling inputs: "area" or "bicubic" (the gdsr protocol's kernel)
    clean_share: float = 0.0  # probability of a noise-free item (upsampling validation adds a clean set when > 0)
    synthetic: int = 32
    use_middlebury: bool = True
    val_scenes: tuple = ("Cloth4", "Wood2")
    val_size: int = 16
    val_every: int = 50
    save_every: int = 25
    num_workers: int = 1
    threads: int = 1
    seed: int = 0
    device: str = "cpu"
    resume: bool = False
    stop_at: Optional[int] = None  # end this run (with a checkpoint) after this step; --resume continues
    init: Optional[str] = None  # start from a pretrained name or a saved folder (default: config defaults)
    # RestorerConfig overrides (config.apply_overrides: version-2 groups, dotted paths or version-1 names), e.g.
    # {"num_layers": 2} or {"guidance": {}}
    model: dict = field(default_factory=dict)
    progress: bool = True

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "TrainConfig":
        known = {f.name for f in dataclasses.fields(cls)}
        d = {k: v for k, v in d.items() if k in known}
        for k in ("sigma", "val_scenes"):
            if k in d and isinstance(d[k], list):
                d[k] = tuple(d[k])
        return cls(**d)


class _StepSampler(Sampler):
    """Indices ``s·B·N + r·B + j`` for steps ``start..steps-1`` (rank ``r`` of ``N``)."""

    def __init__(self, start: int, steps: int, batch: int, rank: int, world: int) -> None:
        self.start, self.steps, self.batch, self.rank, self.world = start, steps, batch, rank, world

    def __iter__(self):
        for s in range(self.start, self.steps):
            base = (s * self.world + self.rank) * self.batch
            yield from range(base, base + self.batch)

    def __len__(self) -> int:
        return max(0, self.steps - self.start) * self.batch


def _dist_env() -> tuple[int, int, int]:
    world = int(os.environ.get("WORLD_SIZE", "1"))
    return int(os.environ.get("RANK", "0")), int(os.environ.get("LOCAL_RANK", "0")), world


def masked_loss(pred: torch.Tensor, gt: torch.Tensor, mask: torch.Tensor, kind: str = "l2") -> torch.Tensor:
    """Mean error over the pixels with ``mask > 0`` (0 if there are none)."""
    valid = (mask > 0).to(pred.dtype)
    err = (pred - gt) * valid
    err = err.pow(2) if kind == "l2" else err.abs()
    return err.sum() / valid.sum().clamp_min(1.0)


@torch.no_grad()
def evaluate(model: DepthRestorer, dataset: Dataset, device: Union[str, torch.device] = "cpu",
             batch_size: int = 4) -> dict:
    """Mean over crops of the per-crop RMSE and MAE on gt-valid pixels (sharded across DDP ranks)."""
    rank, world = (dist.get_rank(), dist.get_world_size()) if dist.is_initialized() else (0, 1)
    sums = torch.zeros(3, dtype=torch.float64)
    idx = list(range(rank, len(dataset), world))
    for i in range(0, len(idx), batch_size):
        items = [dataset[j] for j in idx[i: i + batch_size]]
        depth = torch.stack([s["depth"] for s in items]).to(device)
        rgb = torch.stack([s["rgb"] for s in items]).to(device)
        gt = torch.stack([s["gt"] for s in items]).to(device)
        valid = (torch.stack([s["mask"] for s in items]).to(device) > 0).double()
        err = (model(depth, rgb).double() - gt.double()) * valid
        n = valid.flatten(1).sum(1).clamp_min(1)
        sums[0] += (err.pow(2).flatten(1).sum(1) / n).sqrt().sum().cpu()
        sums[1] += (err.abs().flatten(1).sum(1) / n).sum().cpu()
        sums[2] += len(items)
    if dist.is_initialized():
        dist.all_reduce(sums)
    return {"rmse": float(sums[0] / sums[2].clamp_min(1)), "mae": float(sums[1] / sums[2].clamp_min(1))}


def _save_checkpoint(folder: Path, model: DepthRestorer, opt, step: int, cfg: TrainConfig, history: list,
                     best: dict) -> None:
    tmp = folder.with_name(folder.name + ".tmp")
    tmp.mkdir(parents=True, exist_ok=True)
    model.save(tmp)
    torch.save(opt.state_dict(), tmp / "optimizer.pt")
    (tmp / "trainer.json").write_text(json.dumps({"step": step, "train_config": cfg.to_dict(), "history": history,
                                                  "best": best}, indent=2))
    if folder.exists():
        old = folder.with_name(folder.name + ".old")
        if old.exists():
            for f in old.iterdir():
                f.unlink()
            old.rmdir()
        folder.rename(old)
        tmp.rename(folder)
        for f in old.iterdir():
            f.unlink()
        old.rmdir()
    else:
        tmp.rename(folder)


def load_checkpoint(folder: Union[str, Path], device: Union[str, torch.device] = "cpu"
                    ) -> tuple[DepthRestorer, dict, dict]:
    """Read a checkpoint folder -> ``(model (trainable), optimizer_state, trainer_dict)``."""
    folder = Path(folder)
    model = DepthRestorer.load(folder, trainable=True, map_location=device)
    opt_state = torch.load(folder / "optimizer.pt", map_location=device, weights_only=True)
    trainer = json.loads((folder / "trainer.json").read_text())
    return model, opt_state, trainer


def _initial_model(cfg: TrainConfig) -> DepthRestorer:
    if cfg.init:
        if Path(cfg.init).is_dir():
            base = DepthRestorer.load(cfg.init, trainable=True)
        else:
            base = DepthRestorer.from_pretrained(cfg.init)
        model = DepthRestorer(apply_overrides(base.config, cfg.model), trainable=True)
        # a guidance network switched on by cfg.model starts untrained (it multiplies by 1): only its keys may miss
        missing, unexpected = model.load_state_dict(base.state_dict(), strict=False)
        if unexpected or any(not k.startswith("guidance.") for k in missing):
            raise RuntimeError(f"--init {cfg.init} does not fit the model of --model {cfg.model}: missing "
                               f"{missing[:4]}, unexpected {unexpected[:4]}")
        return model
    return DepthRestorer(apply_overrides(RestorerConfig(), cfg.model), trainable=True)


def _param_groups(model: DepthRestorer, cfg: TrainConfig) -> list[dict]:
    """The optimiser's groups: the layers' scalars and the temperature at ``cfg.lr``; the guidance network's
    weights, when the model has one, at ``cfg.guidance_lr`` (always in this order, so a checkpoint resumes)."""
    net = [p for n, p in model.named_parameters() if p.requires_grad and n.startswith("guidance.")]
    scalars = [p for n, p in model.named_parameters() if p.requires_grad and not n.startswith("guidance.")]
    groups = [{"params": scalars, "lr": cfg.lr}]
    if net:
        groups.append({"params": net, "lr": cfg.guidance_lr})
    return groups


@network_precision("float32")  # as the shipped networks were trained, on any machine
def train(cfg: TrainConfig) -> DepthRestorer:
    """Train per ``cfg``; returns the trained (unwrapped) model. See the module docstring."""
    torch.set_num_threads(max(1, cfg.threads))
    rank, local_rank, world = _dist_env()
    distributed = world > 1
    device = torch.device(cfg.device)
    if distributed and not dist.is_initialized():
        backend = "nccl" if device.type == "cuda" else "gloo"
        if device.type == "cuda":
            device = torch.device("cuda", local_rank)
            torch.cuda.set_device(device)
        dist.init_process_group(backend)
    out = Path(cfg.out)
    ckpt = out / "checkpoint"
    start, history, best = 0, [], {"step": -1, "rmse": math.inf}
    if cfg.resume and (ckpt / "trainer.json").is_file():
        model, opt_state, trainer = load_checkpoint(ckpt, "cpu")
        start, history, best = trainer["step"], trainer["history"], trainer["best"]
    else:
        model, opt_state = _initial_model(cfg), None
    model = model.to(device)
    params = [p for p in model.parameters() if p.requires_grad]
    groups = _param_groups(model, cfg)
    opt = torch.optim.AdamW(groups, lr=cfg.lr, weight_decay=cfg.weight_decay)
    if opt_state is not None:
        opt.load_state_dict(opt_state)

    bases = [g["lr"] for g in groups]

    def set_lr(s: int) -> float:  # cosine from lr to lr/10, a pure function of the step (exact on resume)
        f = 0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * min(s, cfg.steps) / max(1, cfg.steps)))
        for g, base in zip(opt.param_groups, bases):
            g["lr"] = base * f
        return cfg.lr * f

    net = model
    if distributed:
        from torch.nn.parallel import DistributedDataParallel as DDP

        net = DDP(model, device_ids=[device.index] if device.type == "cuda" else None,
                  find_unused_parameters=True)
    end = cfg.steps if cfg.stop_at is None else max(start, min(cfg.steps, cfg.stop_at))
    train_ds, val_sets = make_datasets(cfg.data, crop=cfg.crop, train_length=cfg.steps * cfg.batch_size * world,
                                       val_length=cfg.val_size, val_scenes=cfg.val_scenes, synthetic=cfg.synthetic,
                                       sigma=cfg.sigma, val_sigma=cfg.val_sigma, scale_factor=cfg.scale_factor,
                                       degradation=cfg.degradation, seed=cfg.seed,
                                       use_middlebury=cfg.use_middlebury, downsample=cfg.downsample,
                                       clean_share=cfg.clean_share)
    loader = DataLoader(train_ds, batch_size=cfg.batch_size,
                        sampler=_StepSampler(start, end, cfg.batch_size, rank, world),
                        num_workers=cfg.num_workers, drop_last=False,
                        persistent_workers=False, collate_fn=_collate)
    is_main = rank == 0
    if is_main:
        out.mkdir(parents=True, exist_ok=True)
        (out / "train_config.json").write_text(json.dumps(cfg.to_dict(), indent=2))

    def validate(step: int) -> dict:
        model.eval()
        res = {name: evaluate(model, ds, device) for name, ds in val_sets.items()}
        model.train()
        row = {"step": step, **{f"val_{k}_{m}": v[m] for k, v in res.items() for m in ("rmse", "mae")}}
        row["val_rmse"] = sum(v["rmse"] for v in res.values()) / len(res)
        return row

    from tqdm import tqdm

    bar = tqdm(total=cfg.steps, initial=start, disable=not (cfg.progress and is_main), desc="train",
               dynamic_ncols=True)
    if start == 0 and cfg.val_every > 0:
        row = validate(0)
        history.append(row)
        best = {"step": 0, "rmse": row["val_rmse"]}
        if is_main:
            model.save(out / "best")
            bar.write(_fmt_row(row) + "  (initial parameters)")
    step, t0, running = start, time.perf_counter(), None
    for batch in loader:
        depth, rgb, gt, mask = (batch[k].to(device) for k in ("depth", "rgb", "gt", "mask"))
        lr = set_lr(step)
        pred = net(depth, rgb)
        loss = masked_loss(pred, gt, mask, cfg.loss)
        opt.zero_grad(set_to_none=False)
        loss.backward()
        grads_ok = all(p.grad is None or torch.isfinite(p.grad).all() for p in params)
        if grads_ok and torch.isfinite(loss):  # grads are all-reduced, so every rank decides alike
            opt.step()
        step += 1
        lv = float(loss.detach())
        running = lv if running is None else 0.9 * running + 0.1 * lv
        bar.update(1)
        bar.set_postfix(loss=f"{running:.3g}", lr=f"{lr:.2g}")
        last = step == end
        if cfg.val_every > 0 and (step % cfg.val_every == 0 or step == cfg.steps):
            row = validate(step)
            row.update(train_loss=running, seconds=time.perf_counter() - t0)
            history.append(row)
            if row["val_rmse"] < best["rmse"]:
                best = {"step": step, "rmse": row["val_rmse"]}
                if is_main:
                    model.save(out / "best")
            if is_main:
                bar.write(_fmt_row(row))
        if is_main and (step % cfg.save_every == 0 or last):
            _save_checkpoint(ckpt, model, opt, step, cfg, history, best)
        if distributed and (step % cfg.save_every == 0 or last):
            dist.barrier()
    bar.close()
    if is_main:
        model.save(out / "last")
        (out / "history.json").write_text(json.dumps({"history": history, "best": best}, indent=2))
    return model


def _fmt_row(row: dict) -> str:
    return "step {:>5d}  ".format(row["step"]) + "  ".join(
        f"{k[4:]}={v:.4f}" for k, v in row.items() if k.startswith("val_") and k.endswith("rmse"))


def _collate(items: list) -> dict:
    return {"depth": torch.stack([s["depth"] for s in items]), "rgb": torch.stack([s["rgb"] for s in items]),
            "gt": torch.stack([s["gt"] for s in items]), "mask": torch.stack([s["mask"] for s in items]),
            "name": [s["name"] for s in items]}


__all__ = ["TrainConfig", "evaluate", "load_checkpoint", "masked_loss", "train"]
