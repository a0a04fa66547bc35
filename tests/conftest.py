import json
import shutil
from pathlib import Path

import pytest
import torch

torch.set_num_threads(2)


@pytest.fixture
def scene():
    """A small synthetic RGB-D scene with Gaussian noise and holes (8-bit disparity-like units)."""
    from torch_depth_sr.datasets.synthetic import make_scene

    s = make_scene(48, 64, seed=3)
    g = torch.Generator().manual_seed(0)
    gt = s["gt"][None]
    noisy = gt + 5 * torch.randn(gt.shape, generator=g)
    holes = torch.rand(gt.shape, generator=g) < 0.05
    noisy = torch.where(holes | (gt <= 0), torch.zeros_like(noisy), noisy.clamp_min(1.0))
    return {"depth": noisy, "rgb": s["rgb"][None], "gt": gt, "mask": s["mask"][None]}


def pytest_addoption(parser):
    parser.addoption("--device", action="store", default="cpu",
                     help="device of the device/dtype-parametrised tests (cpu, cuda, cuda:1, ...)")
    parser.addoption("--dtype", action="store", default="float32,float64",
                     help="comma-separated dtypes of the device/dtype-parametrised tests")


_TOLERANCES = {torch.float32: dict(rtol=1e-5, atol=1e-5), torch.float64: dict(rtol=1e-10, atol=1e-12)}


def pytest_generate_tests(metafunc):
    """Tests that take ``float_dtype`` run once per dtype of ``--dtype``."""
    if "float_dtype" in metafunc.fixturenames:
        names = [n.strip() for n in metafunc.config.getoption("--dtype").split(",") if n.strip()]
        metafunc.parametrize("float_dtype", [getattr(torch, n) for n in names], ids=names)


@pytest.fixture
def device(request) -> torch.device:
    """The device named by ``--device``; skips when it is not available here."""
    d = torch.device(request.config.getoption("--device"))
    if d.type == "cuda" and not torch.cuda.is_available():
        pytest.skip(f"--device {d} asked for, but CUDA is not available")
    return d


@pytest.fixture
def tolerance(float_dtype) -> dict:
    """``assert_close`` tolerances for ``float_dtype`` (float32 looser than float64)."""
    return _TOLERANCES[float_dtype]


VERSION1_CONFIGS = Path(__file__).parent / "data" / "version1"
"""``<model>/config.json``: the version-1 files the shipped models were trained and shipped with (until 2026-12-03;
flat, and without the fields added after they were written)."""


@pytest.fixture
def version1_model(tmp_path):
    """``make(name, drop=())``: a model folder holding the shipped ``name``'s state dict and the version-1
    ``config.json`` it shipped with, less the fields in ``drop`` (a file written before they existed)."""
    import torch_depth_sr

    def make(name: str, drop=()):
        values = json.loads((VERSION1_CONFIGS / name / "config.json").read_text())
        folder = tmp_path / "-".join(("v1", name, *drop))
        folder.mkdir()
        (folder / "config.json").write_text(json.dumps({k: v for k, v in values.items() if k not in drop}, indent=2))
        shutil.copy(Path(torch_depth_sr.__file__).parent / "pretrained" / name / "state_dict.pt", folder)
        return folder

    return make
