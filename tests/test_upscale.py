"""Training scenes at a finer pixel pitch (torch_depth_sr.training.upscale): sharp edges stay sharp, slanted surfaces
stay planes, holes stay holes; train-refiner reads them with --upscale."""
import pytest
import torch

from torch_depth_sr._data_root import data_root
from torch_depth_sr.training.refiner import RefinerConfig, _base_model, _scenes
from torch_depth_sr.training.upscale import upscale_scene


def _scene(gt, mask=None):
    h, w = gt.shape[-2:]
    return {"rgb": torch.rand(3, h, w, generator=torch.Generator().manual_seed(0)), "gt": gt,
            "mask": torch.ones(1, h, w) if mask is None else mask, "name": "s"}


@pytest.mark.parametrize("factor", [2, 3])
def test_a_depth_edge_stays_sharp_and_follows_the_coarse_contour(factor):
    yy, xx = torch.meshgrid(torch.arange(24.0), torch.arange(24.0), indexing="ij")
    gt = torch.where(xx + 0.5 * yy < 18, 60.0, 170.0)[None]  # an oblique edge
    big = upscale_scene(_scene(gt), factor)
    assert big["gt"].shape == (1, 24 * factor, 24 * factor) and big["rgb"].shape == (3, 24 * factor, 24 * factor)
    assert set(big["gt"].unique().tolist()) == {60.0, 170.0}
    coarse = torch.nn.functional.interpolate(gt[None], scale_factor=factor, mode="nearest")[0]
    assert (big["gt"] != coarse).float().mean() < 0.05  # the edge moved by at most a fraction of a coarse pixel


def test_a_slanted_surface_stays_a_plane_at_the_finer_pitch():
    xx = torch.arange(30.0).expand(20, 30)
    gt = (40 + 2.7 * xx)[None]  # 2.7 grey levels per third-size pixel
    big = upscale_scene(_scene(gt.round()), 3)["gt"][0]
    fine = (torch.arange(90.0) + 0.5) / 3 - 0.5  # fine pixel centres in coarse coordinates
    exact = (40 + 2.7 * fine).expand(60, 90)
    inner = (slice(6, -6), slice(6, -6))
    assert (big[inner] - exact[inner]).abs().max() <= 1.0  # rounding of the input and of the output
    steps = big[30, 6:-6].diff()
    assert steps.min() >= 0 and steps.max() <= 2  # no terraces of a coarse pixel's height


def test_holes_stay_holes_and_lend_no_value():
    gt = torch.full((1, 16, 16), 100.0)
    mask = torch.ones(1, 16, 16)
    gt[:, 5:9, 5:9], mask[:, 5:9, 5:9] = 0, 0
    big = upscale_scene(_scene(gt, mask), 2)
    assert torch.equal(big["mask"][0, 10:18, 10:18], torch.zeros(8, 8))
    assert torch.equal(big["gt"] == 0, big["mask"] == 0)
    assert big["gt"][big["mask"] > 0].unique().tolist() == [100.0]


def test_train_refiner_reads_the_2006_scenes_upscaled():
    root = data_root()
    if not (root / "middlebury2006").is_dir():
        pytest.skip(f"middlebury2006 not found under {root} (set TORCH_DEPTH_SR_DATA)")
    plain, _ = _scenes(RefinerConfig(synthetic=0, data=str(root)))
    train, valid = _scenes(RefinerConfig(synthetic=0, upscale=2, data=str(root)))
    assert {s["name"] for s in valid} == {"Cloth4@x2", "Wood2@x2"}
    assert [s["gt"].shape[-1] for s in train] == [2 * s["gt"].shape[-1] for s in plain]


@pytest.mark.parametrize("field, value", [("select", "psnr"), ("upscale", 0)])
def test_refiner_settings_are_checked(field, value):
    with pytest.raises(ValueError, match=field):
        _base_model(RefinerConfig(**{field: value}))
