"""Training the edge refiner (:mod:`torch_depth_sr.refiner`) on the frozen model's outputs.

The unrolled model is too slow on this CPU to be trained end to end with a CNN after it, and it does not need to
be: its parameters stay as they are, so its outputs are computed once per training image (full images, every
degradation) and the refiner learns on random crops of them. What the refiner learns from is exactly what the model
hands it at inference: a copy of the model runs with a stand-in refiner that records its arguments
(:func:`_recording_model`), so
the bounds, the filled holes and the noise level are the model's own. Data, as for every trained parameter of the
project: the Middlebury 2006 scenes (two held out for validation) and procedural synthetic scenes.

Two tasks (``task``):

* ``"upsample"`` (the ``gdsr`` protocol, ``shared/docs/benchmark.md``): crop to a multiple of ``s``, antialiased
  bicubic downsampling (mask-aware, :class:`~torch_depth_sr.transforms.Downsample`), Gaussian noise of σ =
  ``noise`` on a 0–255 scale of the image's ground-truth range on the measured low-resolution pixels; every
  factor × noise.
* ``"denoise"``: the ``paper`` and ``sensor`` degradations (:mod:`torch_depth_sr.degradations`) at every σ of
  ``noises`` (grey levels), ``seeds`` draws each; the refiner then runs when K = I.

Output: ``<out>/best`` and ``<out>/last``, :meth:`DepthRestorer.save` folders of the base model with
``refiner={"channels": ..., "layers": ..., "task": ...}`` (the task trained for) and the refiner's weights, and
``<out>/history.json``.
:func:`evaluate_refiners` scores saved models on one recipe's validation samples (runs compared on one set, e.g. at
the test pitch, whatever pitch each was trained at).
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np
import torch
from torch import nn

from ..config import RestorerConfig, apply_overrides
from ..model import DepthRestorer
from ..post_steps import post_steps
from ..precision import network_precision
from ..refiner import EdgeRefiner
from ..transforms import Downsample
from .datasets import middlebury_records

__all__ = ["RefinerConfig", "degrade_for_refiner", "evaluate_refiners", "train_refiner"]


@dataclass
class RefinerConfig:
    """Settings of :func:`train_refiner` (the CLI flags mirror these names)."""
    out: str = "runs/refiner"
    task: str = "upsample"  # "upsample" (gdsr degradation, K ≠ I) or "denoise" (paper/sensor degradations, K = I)
    # the Middlebury 2006 scenes as "middlebury2006" (the project's copy: official third-size maps with their holes)
    # or as "gdsr" (the files of the same eleven scenes in the guided-SR test set, filled and in that set's own
    # rendering of the ground truth, which differs from the official maps at depth edges)
    source: str = "middlebury2006"
    # RestorerConfig overrides of the frozen model (config.apply_overrides: version-2 groups, dotted paths or
    # version-1 names); task "upsample" without ``init`` defaults to K = bicubic
    base: dict = field(default_factory=dict)
    init: Optional[str] = None  # the frozen model from a pretrained name or a saved folder (then ``base`` overrides it)
    factors: tuple = (4, 8, 16)  # task "upsample"
    downsample: str = "bicubic"  # task "upsample": the kernel of the training inputs ("bicubic" or "area")
    # task "upsample": σ on a 0–255 scale of each image's ground-truth range; "denoise": σ in grey levels
    noises: tuple = (0.0, 5.0, 10.0)
    tracks: tuple = ("paper", "sensor")  # task "denoise": the degradations
    seeds: int = 1  # task "denoise": draws of each degradation per scene and σ
    loss: str = "l1"  # "l1" or "l2", on known pixels in units of each image's range/10
    synthetic: int = 16  # procedural scenes (seeds 0..n−1), 240×320
    # the Middlebury scenes (training and validation) at this many times their size (training/upscale.py): the
    # pixel pitch of a full-size capture is upscale 3
    upscale: int = 1
    select: str = "rmse"  # the validation metric that picks ``best``: "rmse" or "mae"
    # start from the refiner ``init`` carries (same channels and layers) instead of random weights: to fine-tune a
    # shipped refiner on new degradations (step 0's validation is then that refiner's, and best/ must beat it)
    warm_start: bool = False
    val_scenes: tuple = ("Cloth4", "Wood2")
    channels: int = 32
    layers: int = 6
    steps: int = 2000
    batch_size: int = 16
    crop: int = 64
    lr: float = 1e-3
    val_every: int = 250
    seed: int = 0
    threads: int = 1
    data: Optional[str] = None
    progress: bool = True


def degrade_for_refiner(gt: torch.Tensor, mask: torch.Tensor, factor: int, noise: float,
                        generator: torch.Generator, kernel: str = "bicubic"
                        ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``gt``, ``mask`` (1,1,H,W) → the cropped ``gt``, ``mask`` and the low-resolution input (0 where missing);
    ``kernel`` of :class:`~torch_depth_sr.transforms.Downsample` (``"area"``: the Park et al. inputs of
    ``upsample-b``, whose noise is i.i.d. Gaussian on area-downsampled maps, measured σ ≈ 5 grey levels)."""
    h, w = (gt.shape[-2] // factor) * factor, (gt.shape[-1] // factor) * factor
    gt, mask = gt[..., :h, :w], mask[..., :h, :w]
    low = Downsample(factor, kernel)({"depth": gt * (mask > 0)})["depth"]
    measured = gt[mask > 0]
    span = float(measured.max() - measured.min()) if measured.numel() else 0.0
    noisy = low + noise * span / 255.0 * torch.randn(low.shape, generator=generator)
    low = torch.where(low > 0, noisy.clamp_min(1e-3), torch.zeros_like(low))
    return gt, mask, low


def _scenes(cfg: RefinerConfig) -> tuple[list[dict], list[dict]]:
    from ..datasets.synthetic import make_scene

    val = {s.lower() for s in cfg.val_scenes}
    train, valid = [], []
    if cfg.source == "gdsr":
        from .._data_root import data_root
        from ..datasets.gdsr import FITTING, FOLDER, MIDDLEBURY_SCENES, gdsr_images

        root = Path(cfg.data) if cfg.data else data_root()
        if (root / FOLDER / "Middlebury").is_dir():
            for img in gdsr_images(root, "Middlebury", only=sorted(FITTING)):  # never a held-out file
                gt = torch.from_numpy(img.depth)[None]
                s = {"gt": gt, "mask": (gt > 0).float(), "name": MIDDLEBURY_SCENES[img.index],
                     "rgb": torch.from_numpy(img.rgb.copy()).permute(2, 0, 1).float() / 255}
                (valid if s["name"].lower() in val else train).append(s)
    elif cfg.source == "middlebury2006":
        for r in middlebury_records(cfg.data):
            s = r.load()
            (valid if r.name.lower() in val else train).append({k: s[k] for k in ("rgb", "gt", "mask", "name")})
    else:
        raise ValueError(f"source={cfg.source!r}; allowed are 'middlebury2006' and 'gdsr'")
    if cfg.upscale > 1:
        from .upscale import upscale_scene

        train, valid = ([upscale_scene(s, cfg.upscale) for s in group] for group in (train, valid))
    for j in range(cfg.synthetic):
        s = make_scene(240, 320, seed=j)
        train.append({k: s[k] for k in ("rgb", "gt", "mask", "name")})
    if not valid:  # no Middlebury data here (CI): validate on two held-out synthetic scenes
        valid = [{k: s[k] for k in ("rgb", "gt", "mask", "name")}
                 for s in (make_scene(240, 320, seed=10_000 + j) for j in range(2))]
    return train, valid


class _Recorder(nn.Module):
    """Stands in for the refiner inside the model: keeps what the model hands it and returns ``x`` unchanged."""

    def forward(self, x, lowres, rgb, noise):
        self.args = (x, lowres, rgb, noise)
        return x


def _recording_model(base: DepthRestorer, task: str) -> tuple[DepthRestorer, _Recorder]:
    """A copy of ``base`` (its settings and parameters) whose refiner, in the post-step of ``task`` (where a trained
    refiner runs), is a :class:`_Recorder`; a refiner ``base`` has is left out. ``base`` is not changed."""
    config = base.config.replace(refiner={"task": task})
    model = DepthRestorer(config)
    missing, unexpected = model.load_state_dict(
        {k: v for k, v in base.state_dict().items() if not k.startswith("refiner.")}, strict=False)
    if unexpected or any(not k.startswith("refiner.") for k in missing):
        raise RuntimeError(f"the recording copy does not fit the model: missing {missing[:4]}, unexpected "
                           f"{unexpected[:4]}")
    recorder = _Recorder()
    model.refiner = recorder
    model.post = post_steps(config, recorder)
    return model.to(base.block_matcher.log_temperature.device).eval(), recorder


def _degraded(s: dict, cfg: RefinerConfig, g: torch.Generator, job: tuple) -> tuple[torch.Tensor, ...]:
    """``(input, rgb, gt, mask)`` (1,C,·,·) of one job: ``(factor, noise)`` (upsample) or ``(track, σ, seed)``."""
    if cfg.task == "upsample":
        f, n = job
        gt, mask, low = degrade_for_refiner(s["gt"][None], s["mask"][None], f, n, g, cfg.downsample)
        return low, s["rgb"][None, :, : gt.shape[-2], : gt.shape[-1]], gt, mask
    from ..degradations import make_degradation

    track, sigma, seed = job
    d = make_degradation(track, sigma=sigma, seed=seed)(s)
    return d["depth"][None], s["rgb"][None], s["gt"][None], s["mask"][None]


def _jobs(cfg: RefinerConfig) -> list[tuple]:
    if cfg.task == "upsample":
        return [(f, n) for f in cfg.factors for n in cfg.noises]
    return [(t, n, cfg.seed * 1000 + k) for t in cfg.tracks for n in cfg.noises for k in range(cfg.seeds)]


@torch.no_grad()
def _samples(base: DepthRestorer, refiner: EdgeRefiner, scenes: list[dict], cfg: RefinerConfig,
             tag: str) -> list[dict]:
    """The frozen model's output on every scene × degradation and the refiner's whole-image inputs, in the
    model's normalised units (``gt`` too; ``scale`` converts back)."""
    from tqdm import tqdm

    out = []
    model, recorder = _recording_model(base, cfg.task)
    jobs = [(s, j) for s in scenes for j in _jobs(cfg)]
    for i, (s, job) in enumerate(tqdm(jobs, desc=f"model outputs ({tag})", disable=not cfg.progress)):
        g = torch.Generator().manual_seed(cfg.seed * 100_003 + i)
        low, rgb, gt, mask = _degraded(s, cfg, g, job)
        info = model.restore_with_details(torch.where(low > 0, low, torch.full_like(low, float("nan"))), rgb).info
        x, filled, guide, level = (a.float() for a in recorder.args)
        offset, scale = info["offset"][0], info["scale"][0]
        phi, lo, hi, unit = refiner.prepare(x, filled, guide, level)
        out.append({"x": x, "phi": phi, "lo": lo, "hi": hi, "unit": unit, "gt": (gt - offset) / scale,
                    "mask": mask, "scale": scale, "factor": x.shape[-1] // low.shape[-1], "job": job,
                    "name": f"{s['name']}/" + "/".join(f"{v:g}" if isinstance(v, float) else str(v) for v in job)})
    return out


_CROPPED = ("x", "phi", "lo", "hi", "gt", "mask")


def _crop_batch(samples: list[dict], cfg: RefinerConfig, rng: np.random.Generator) -> dict:
    """``batch_size`` random crops (at multiples of the factor, optionally mirrored), stacked."""
    parts: dict = {k: [] for k in (*_CROPPED, "unit")}
    c = cfg.crop
    for _ in range(cfg.batch_size):
        s = samples[int(rng.integers(len(samples)))]
        f = s["factor"]
        h, w = s["x"].shape[-2:]
        i = int(rng.integers(0, (h - c) // f + 1)) * f
        j = int(rng.integers(0, (w - c) // f + 1)) * f
        flip = rng.random() < 0.5
        for k in _CROPPED:
            v = s[k][..., i: i + c, j: j + c]
            parts[k].append(v.flip(-1) if flip else v)
        parts["unit"].append(s["unit"])
    return {k: torch.cat(v) for k, v in parts.items()}


def _loss(refiner: EdgeRefiner, batch: dict, loss: str = "l1") -> torch.Tensor:
    """L1 (or squared) error on known pixels in units of each image's ``unit`` (unit-free), mean over the batch's
    pixels."""
    pred = refiner.correct(batch["x"], batch["phi"], batch["lo"], batch["hi"], batch["unit"])
    valid = (batch["mask"] > 0).to(pred.dtype)
    err = (pred - batch["gt"]) / batch["unit"]
    err = err.abs() if loss == "l1" else err.square()
    return (err * valid).sum() / valid.sum().clamp_min(1)


@torch.no_grad()
def _validate(refiner: EdgeRefiner, samples: list[dict]) -> dict:
    """Mean RMSE and MAE (in the input's units) over the validation samples (known pixels) of the refined and the
    unrefined outputs."""
    rows = []
    for s in samples:
        valid = s["mask"] > 0
        pred = refiner.correct(s["x"], s["phi"], s["lo"], s["hi"], s["unit"])
        errors = [((v - s["gt"])[valid] * s["scale"]) for v in (pred, s["x"])]
        rows.append([float(e.square().mean().sqrt()) for e in errors] + [float(e.abs().mean()) for e in errors])
    rmse, rmse_model, mae, mae_model = np.mean(rows, 0).tolist()
    return {"rmse": rmse, "rmse_model": rmse_model, "mae": mae, "mae_model": mae_model}


def _base_model(cfg: RefinerConfig) -> DepthRestorer:
    """The frozen model: ``cfg.init`` (a pretrained name or a saved folder) with ``cfg.base`` overrides, or the
    defaults with them."""
    if cfg.task not in ("upsample", "denoise"):
        raise ValueError(f"task={cfg.task!r}; allowed are 'upsample' and 'denoise'")
    if cfg.loss not in ("l1", "l2"):
        raise ValueError(f"loss={cfg.loss!r}; allowed are 'l1' and 'l2'")
    if cfg.select not in ("rmse", "mae"):
        raise ValueError(f"select={cfg.select!r}; allowed are 'rmse' and 'mae'")
    if cfg.upscale < 1:
        raise ValueError(f"upscale={cfg.upscale!r}; allowed is a whole number >= 1")
    if cfg.init is None:
        start = RestorerConfig(degradation="bicubic") if cfg.task == "upsample" else RestorerConfig()
        return DepthRestorer(apply_overrides(start, cfg.base)).eval()
    return _saved_model(cfg.init, cfg.base)


def _saved_model(name: str, overrides: Optional[dict] = None) -> DepthRestorer:
    """A saved folder or a pretrained name, in eval mode, with ``overrides`` of its settings
    (:func:`~torch_depth_sr.config.apply_overrides`; its parameters must still fit)."""
    model = DepthRestorer.load(name) if Path(name).is_dir() else DepthRestorer.from_pretrained(name)
    if overrides:
        changed = DepthRestorer(apply_overrides(model.config, overrides))
        changed.load_state_dict(model.state_dict())
        model = changed
    return model.eval()


def _warm_start(refiner: EdgeRefiner, base: DepthRestorer, cfg: RefinerConfig) -> None:
    """``refiner`` takes the weights of the refiner ``base`` (``cfg.init``) carries; its shape must be the same."""
    own = base.refiner
    if cfg.init is None or own is None:
        raise ValueError(f"warm_start needs an init model with an edge refiner; init={cfg.init!r} has none")
    shape = (base.config.refiner.channels, base.config.refiner.layers)
    if shape != (cfg.channels, cfg.layers):
        raise ValueError(f"warm_start: {cfg.init!r}'s refiner has channels, layers = {shape}; "
                         f"got channels={cfg.channels}, layers={cfg.layers}")
    refiner.load_state_dict(own.state_dict())


def _export(base: DepthRestorer, refiner: EdgeRefiner, cfg: RefinerConfig, folder: Path) -> None:
    model = DepthRestorer(base.config.replace(refiner={"channels": cfg.channels, "layers": cfg.layers,
                                                       "task": cfg.task}))
    state = {**{k: v for k, v in base.state_dict().items() if not k.startswith("refiner.")},
             **{f"refiner.{k}": v for k, v in refiner.state_dict().items()}}
    model.load_state_dict(state)
    model.save(folder)


@network_precision("float32")  # as the shipped networks were trained, on any machine
def train_refiner(cfg: RefinerConfig) -> EdgeRefiner:
    """Compute the frozen model's outputs, train the refiner on crops of them, export the best by validation."""
    torch.set_num_threads(max(1, cfg.threads))
    torch.manual_seed(cfg.seed)
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "refiner_config.json").write_text(json.dumps(asdict(cfg), indent=2))
    base = _base_model(cfg)
    train_scenes, val_scenes = _scenes(cfg)
    t0 = time.perf_counter()
    refiner = EdgeRefiner(cfg.channels, cfg.layers)
    if cfg.warm_start:
        _warm_start(refiner, base, cfg)
    train_samples = _samples(base, refiner, train_scenes, cfg, "training")
    val_samples = _samples(base, refiner, val_scenes, cfg, "validation")
    prepare_seconds = time.perf_counter() - t0
    opt = torch.optim.Adam(refiner.parameters(), lr=cfg.lr)
    rng = np.random.default_rng(cfg.seed)
    history = [{"step": 0, **_validate(refiner, val_samples)}]
    best = {"step": 0, cfg.select: history[0][cfg.select]}
    _export(base, refiner, cfg, out / "best")
    from tqdm import tqdm

    bar = tqdm(range(1, cfg.steps + 1), desc="train refiner", disable=not cfg.progress)
    t1 = time.perf_counter()
    for step in bar:
        for g in opt.param_groups:  # cosine from lr to lr/10
            g["lr"] = cfg.lr * (0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * (step - 1) / cfg.steps)))
        loss = _loss(refiner, _crop_batch(train_samples, cfg, rng), cfg.loss)
        opt.zero_grad()
        loss.backward()
        opt.step()
        bar.set_postfix(loss=f"{loss.item():.4g}")
        if step % cfg.val_every == 0 or step == cfg.steps:
            row = {"step": step, **_validate(refiner, val_samples), "seconds": time.perf_counter() - t1}
            history.append(row)
            bar.write(f"step {step:>5d}  val rmse {row['rmse']:.4f} mae {row['mae']:.4f} "
                      f"(model alone {row['rmse_model']:.4f} / {row['mae_model']:.4f})")
            if row[cfg.select] < best[cfg.select]:
                best = {"step": step, cfg.select: row[cfg.select]}
                _export(base, refiner, cfg, out / "best")
    _export(base, refiner, cfg, out / "last")
    (out / "history.json").write_text(json.dumps({"history": history, "best": best,
                                                  "prepare_seconds": prepare_seconds,
                                                  "parameters": sum(p.numel() for p in refiner.parameters())},
                                                 indent=2))
    return refiner


def _settings(config: RestorerConfig) -> dict:
    """Every setting of ``config`` by its dotted path (``"block_matching.k"``; a group that is off: its name, None)."""
    out = {}

    def walk(prefix: str, value) -> None:
        if isinstance(value, dict) and value:
            for k, v in value.items():
                walk(f"{prefix}.{k}" if prefix else k, v)
        else:
            out[prefix] = value

    walk("", {k: v for k, v in config.to_dict().items() if k != "version"})
    return out


@network_precision("float32")  # as the shipped networks were trained, on any machine
def evaluate_refiners(cfg: RefinerConfig, models: list[str]) -> list[dict]:
    """The validation figures of saved models (folders or pretrained names, each with a refiner for ``cfg.task``) on
    the validation samples of ``cfg`` (its scenes, degradations and ``upscale``): one row per model and group (all,
    then each factor or track) with ``rmse``, ``mae`` and the frozen model's ``rmse_model``, ``mae_model``. The
    refiners see the frozen model of ``cfg`` (its inputs are recorded once); a model whose own frozen part differs
    is refused."""
    from ..errors import UsageError

    torch.set_num_threads(max(1, cfg.threads))
    base = _base_model(cfg)
    loaded = {}
    for name in models:
        model = _saved_model(name)
        if model.config.refiner is None or model.config.refiner.task != cfg.task:
            raise UsageError(f"{name}: has no refiner for task {cfg.task!r} (refiner {model.config.refiner})")
        settings = [_settings(m.config.replace(refiner=None)) for m in (model, base)]
        weights = [{k: v for k, v in m.state_dict().items() if not k.startswith("refiner.")} for m in (model, base)]
        differ = sorted(k for k in set(settings[0]) | set(settings[1])
                        if settings[0].get(k, "(absent)") != settings[1].get(k, "(absent)"))
        differ += sorted(k for k in weights[1] if k not in weights[0] or not torch.equal(weights[0][k], weights[1][k]))
        if differ:
            raise UsageError(f"{name}: its frozen model is not this recipe's (--init/--base); it differs in {differ}")
        loaded[name] = model.refiner.eval()
    _, val_scenes = _scenes(cfg)
    samples = _samples(base, EdgeRefiner(cfg.channels, cfg.layers), val_scenes, cfg, "validation")
    groups = {"all": samples}
    for s in samples:  # the job's first field: the factor (upsample) or the track (denoise)
        groups.setdefault(str(s["job"][0]), []).append(s)
    rows = []
    with torch.no_grad():
        for name, refiner in loaded.items():
            rows += [{"model": name, "group": g, "samples": len(group), **_validate(refiner, group)}
                     for g, group in groups.items()]
    return rows
