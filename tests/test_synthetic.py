"""Procedural synthetic RGB-D scenes."""


import numpy as np
import pytest
import torch

from torch_depth_sr.datasets import SyntheticScenes, make_scene
from torch_depth_sr.errors import DepthSRError


def test_shapes_ranges_and_keys():
    s = make_scene(96, 128, seed=0)
    assert s["rgb"].shape == (3, 96, 128) and s["rgb"].dtype == torch.float32
    assert s["gt"].shape == (1, 96, 128) and s["gt"].dtype == torch.float32
    assert float(s["rgb"].min()) >= 0 and float(s["rgb"].max()) <= 1
    assert 20.0 <= float(s["gt"].min()) and float(s["gt"].max()) <= 230.0
    assert torch.equal(s["mask"], torch.ones_like(s["gt"])) and torch.equal(s["depth"], s["gt"])
    assert s["scale"] == 3.0 and s["dataset"] == "synthetic" and s["name"] == "synthetic_0"


def test_seeded():
    a, b, c = make_scene(64, 80, 5), make_scene(64, 80, 5), make_scene(64, 80, 6)
    assert torch.equal(a["gt"], b["gt"]) and torch.equal(a["rgb"], b["rgb"])
    assert not torch.equal(a["gt"], c["gt"])


def test_content_edges():
    """Depth edges come with colour edges; painted marks are colour edges without depth edges."""
    n_paint, n_obj = 0, 0
    for seed in range(8):
        s = make_scene(120, 160, seed)
        gt, rgb, labels, paint = s["gt"][0].numpy(), s["rgb"].numpy(), s["labels"][0].numpy(), s["paint"][0].numpy() > 0
        n_obj += labels.max()
        dgt = np.abs(np.diff(gt, axis=1)) > 5
        drgb = np.abs(np.diff(rgb, axis=2)).sum(0) > 0.02
        if dgt.sum():
            assert (dgt & drgb).sum() / dgt.sum() > 0.5  # colour edges follow depth edges
        pe = np.diff(paint.astype(np.int8), axis=1) != 0
        if pe.any():
            n_paint += 1
            # at painted boundaries (away from objects), the depth is smooth
            bg = (labels[:, 1:] == 0) & (labels[:, :-1] == 0)
            assert np.abs(np.diff(gt, axis=1))[pe & bg].max(initial=0) < 1.0
    assert n_paint >= 4 and n_obj >= 20


def test_dataset_and_errors():
    ds = SyntheticScenes(n=3, size=(32, 48), seed=1)
    assert len(ds) == 3
    assert ds[0]["gt"].shape == (1, 32, 48)
    assert torch.equal(ds[-1]["gt"], ds[2]["gt"])
    with pytest.raises(IndexError):
        ds[3]
    with pytest.raises(DepthSRError, match="16"):
        make_scene(8, 8, 0)
    batch = torch.utils.data.default_collate([ds[0], ds[1]])
    assert batch["gt"].shape == (2, 1, 32, 48)
