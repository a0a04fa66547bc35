"""Training: crop datasets, DataLoader workers with RestoreDepth, checkpoints, DDP with gloo, CLI."""
import argparse
import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from torch.utils.data import DataLoader

from torch_depth_sr import DepthRestorer
from torch_depth_sr.errors import DepthSRError
from torch_depth_sr.training import CropDataset, TrainConfig, load_checkpoint, masked_loss, train
from torch_depth_sr.training.cli import add_train_parser, config_from_args
from torch_depth_sr.transforms import AddGaussianNoise, AddHoles, Compose, RestoreDepth

TINY = dict(num_layers=2, block_matching={"search_window": 7, "k": 4})
ROOT = Path(__file__).resolve().parents[1]


def tiny_config(out, **kw) -> TrainConfig:
    base = dict(out=str(out), steps=2, batch_size=2, crop=32, synthetic=3, use_middlebury=False, val_size=2,
                val_every=2, save_every=1, num_workers=0, model=dict(TINY), progress=False)
    base.update(kw)
    return TrainConfig(**base)


def _params(model) -> torch.Tensor:
    return torch.cat([p.detach().flatten() for p in model.parameters()])


class TestCropDataset:
    def test_items(self):
        ds = CropDataset(use_middlebury=False, synthetic=2, synthetic_size=(48, 48), crop=32, length=6)
        s = ds[3]
        assert sorted(s) == ["depth", "gt", "mask", "name", "rgb"]
        assert s["depth"].shape == (1, 32, 32) and s["rgb"].shape == (3, 32, 32)
        assert torch.equal(ds[3]["depth"], s["depth"])  # a pure function of (seed, index)
        assert not torch.equal(ds[4]["depth"], s["depth"])
        with pytest.raises(IndexError):
            ds[6]

    def test_upsampling_items(self):
        ds = CropDataset(use_middlebury=False, synthetic=1, synthetic_size=(48, 48), crop=32, scale_factor=4)
        s = ds[0]
        assert s["depth"].shape == (1, 8, 8) and s["gt"].shape == (1, 32, 32)

    def test_custom_degradation(self):
        ds = CropDataset(use_middlebury=False, synthetic=1, synthetic_size=(48, 48), crop=32,
                         degradation=Compose([AddGaussianNoise(3.0), AddHoles()]))
        assert (ds[0]["depth"] == 0).any()

    def test_split_policy(self):
        with pytest.raises(DepthSRError, match="only 2006"):
            CropDataset(years=(2005,), synthetic=1)

    def test_no_scenes(self, tmp_path):
        with pytest.raises(DepthSRError, match="no scenes"):
            CropDataset(root=tmp_path, synthetic=0)

    def test_middlebury_2006_only(self):
        from torch_depth_sr._data_root import require_data_root

        require_data_root("middlebury2006")
        ds = CropDataset(synthetic=0, crop=64, length=4, exclude=("Cloth4", "Wood2"))
        assert ds.records and all(r.year == 2006 for r in ds.records)
        assert not {"cloth4", "wood2"} & {r.name.lower() for r in ds.records}
        assert ds[0]["name"].split("@")[0] in ds.scene_names


def test_dataloader_workers_with_restore_depth():
    restore = RestoreDepth(**TINY)
    ds = CropDataset(use_middlebury=False, synthetic=2, synthetic_size=(48, 48), crop=32, length=4,
                     degradation=Compose([AddGaussianNoise(5.0), AddHoles(), restore]))
    loader = DataLoader(ds, batch_size=2, num_workers=2)
    batches = list(loader)
    assert len(batches) == 2
    b = batches[0]
    assert b["depth"].shape == (2, 1, 32, 32) and (b["depth"] > 0).all()  # holes filled by the restorer
    assert b["name"][0].startswith("synthetic_")


def test_masked_loss_ignores_invalid():
    pred, gt = torch.zeros(1, 1, 2, 2), torch.tensor([[[[1.0, 2.0], [100.0, 100.0]]]])
    mask = torch.tensor([[[[1.0, 1.0], [0.0, 0.0]]]])
    assert masked_loss(pred, gt, mask, "l2") == pytest.approx(2.5)
    assert masked_loss(pred, gt, mask, "l1") == pytest.approx(1.5)


def test_train_checkpoint_resume_round_trip(tmp_path):
    full = train(tiny_config(tmp_path / "full", steps=3))
    train(tiny_config(tmp_path / "part", steps=3, stop_at=2))  # an interrupted run
    model, opt_state, trainer = load_checkpoint(tmp_path / "part" / "checkpoint")
    assert trainer["step"] == 2 and opt_state["state"]
    assert all(p.requires_grad for p in model.parameters())
    resumed = train(tiny_config(tmp_path / "part", steps=3, resume=True))
    assert torch.allclose(_params(resumed), _params(full), atol=1e-5)
    # the trained parameters moved and every one is learnable
    assert not torch.allclose(_params(full), _params(DepthRestorer(trainable=True, **TINY)))
    best = DepthRestorer.load(tmp_path / "full" / "best")
    assert not any(p.requires_grad for p in best.parameters())
    hist = json.loads((tmp_path / "full" / "history.json").read_text())
    assert hist["history"][0]["step"] == 0 and "val_sensor_rmse" in hist["history"][-1]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _ddp_worker(rank: int, world: int, port: int, out: str) -> None:
    os.environ.update(MASTER_ADDR="127.0.0.1", MASTER_PORT=str(port), RANK=str(rank), WORLD_SIZE=str(world),
                      LOCAL_RANK=str(rank))
    import torch.distributed as dist

    model = train(tiny_config(out, steps=2, val_every=0, save_every=2))
    torch.save(_params(model), Path(out) / f"params_rank{rank}.pt")
    dist.destroy_process_group()


def test_ddp_two_cpu_processes_keep_parameters_identical(tmp_path):
    import torch.multiprocessing as mp

    mp.spawn(_ddp_worker, args=(2, _free_port(), str(tmp_path)), nprocs=2, join=True)
    p0 = torch.load(tmp_path / "params_rank0.pt", weights_only=True)
    p1 = torch.load(tmp_path / "params_rank1.pt", weights_only=True)
    assert torch.equal(p0, p1)
    assert not torch.allclose(p0, _params(DepthRestorer(trainable=True, **TINY)))
    assert (tmp_path / "checkpoint" / "state_dict.pt").is_file()


def test_cli_parser_and_command(tmp_path):
    p = argparse.ArgumentParser()
    add_train_parser(p.add_subparsers(dest="command"))
    args = p.parse_args(["train", "--out", str(tmp_path), "--steps", "1", "--crop", "32", "--batch-size", "1",
                         "--synthetic-only", "--synthetic", "2", "--val-size", "1", "--val-every", "1",
                         "--workers", "0", "--no-progress", "--model", json.dumps(TINY)])
    cfg = config_from_args(args)
    assert cfg.model == TINY and cfg.use_middlebury is False
    assert args.func(args) == 0
    assert (tmp_path / "best" / "config.json").is_file()


def test_example_train_unrolled(tmp_path):
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "train_unrolled.py"), "--steps", "2", "--crop", "32",
                        "--out", str(tmp_path), "--tiny"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]


def test_example_restore_in_dataloader():
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "restore_in_dataloader.py"), "--workers", "2",
                        "--frames", "2", "--size", "48", "64"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]


def test_example_quickstart():
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "quickstart.py")], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0 and "restored RMSE" in r.stdout, r.stderr[-2000:]


@pytest.mark.parametrize("guidance_net", [False, True])
def test_every_parameter_that_requires_grad_gets_a_finite_gradient(guidance_net):
    """Issue 10 item 3: the parameters that learn are exactly the ones that get gradients (issue 14: the
    guidance network's weights too)."""
    from torch_depth_sr import DepthRestorer
    from torch_depth_sr.datasets.synthetic import make_scene

    s = make_scene(40, 48, seed=2)
    g = torch.Generator().manual_seed(0)
    y = (s["gt"] + 3 * torch.randn(s["gt"].shape, generator=g)).clamp_min(1)[None]
    model = DepthRestorer(trainable=True, num_layers=3, guidance={} if guidance_net else None)
    loss = (model(y, s["rgb"][None]) - s["gt"][None]).square().mean()
    loss.backward()
    trainable = {n for n, p in model.named_parameters() if p.requires_grad}
    with_grad = {n for n, p in model.named_parameters() if p.grad is not None and torch.isfinite(p.grad).all()}
    assert trainable == with_grad, sorted(trainable ^ with_grad)
    assert "block_matcher.log_color_weight" not in trainable and "block_matcher.log_temperature" in trainable
    assert any(n.startswith("guidance.") for n in trainable) == guidance_net


def test_guided_training_starts_from_a_scalar_model_and_learns_the_network(tmp_path):
    """--init of a model without a guidance network and --model '{"guidance": {}}': the scalars are loaded,
    the network starts untrained (multiplies by 1) and learns at its own rate; the checkpoint resumes."""
    scalar = DepthRestorer(**TINY, weights={"lam": 0.7})
    scalar.save(tmp_path / "scalar")
    cfg = tiny_config(tmp_path / "run", steps=2, val_every=0, init=str(tmp_path / "scalar"),
                      model={"guidance": {"channels": 4}}, guidance_lr=1e-2)
    model = train(cfg)
    assert model.config.guidance is not None and model.config.weights.lam == 0.7
    heads = torch.cat([p.detach().flatten() for p in model.guidance.heads.parameters()])
    assert heads.abs().max() > 0  # moved from its zero start
    _, opt_state, _ = load_checkpoint(tmp_path / "run" / "checkpoint")
    assert len(opt_state["param_groups"]) == 2
    loaded = DepthRestorer.load(tmp_path / "run" / "last")
    assert torch.equal(_params(loaded), _params(model))
