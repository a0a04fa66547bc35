"""Track gdsr (issue 14 item 1): readers, the degradation, the RMSE conventions and the command's rows.

The protocol is checked against an independent NumPy implementation of Pillow's bicubic resampling (its
``precompute_coeffs`` with the a = -0.5 cubic), and against Pillow itself where it is installed.
"""
import json

import numpy as np
import pytest
import torch

from torch_depth_sr._data_root import require_data_root
from torch_depth_sr.cli import main
from torch_depth_sr.datasets.gdsr import FITTING, SETS, GDSRImage, gdsr_images, list_names, resolve_set
from torch_depth_sr.evaluation.gdsr import (_run_model, add_noise, bicubic, crop_to_multiple, degrade, make_model,
                                            resize_pillow, rmse)

# ---------------------------------------------------------------- an independent Pillow bicubic (NumPy, float64)


def _cubic(x, a=-0.5):
    x = abs(x)
    if x < 1:
        return ((a + 2) * x - (a + 3)) * x * x + 1
    if x < 2:
        return (((x - 5) * x + 8) * x - 4) * a
    return 0.0


def _pillow_matrix(n_in: int, n_out: int) -> np.ndarray:
    """Pillow's resampling weights (libImaging/Resample.c, precompute_coeffs) as an (n_out, n_in) matrix."""
    scale = n_in / n_out
    fs = max(scale, 1.0)
    support = 2.0 * fs
    m = np.zeros((n_out, n_in))
    for xx in range(n_out):
        c = (xx + 0.5) * scale
        lo, hi = max(int(c - support + 0.5), 0), min(int(c + support + 0.5), n_in)
        w = np.array([_cubic((x - c + 0.5) / fs) for x in range(lo, hi)])
        m[xx, lo:hi] = w / w.sum()
    return m


def _pillow_resize(a: np.ndarray, h: int, w: int) -> np.ndarray:
    """Horizontal pass, then vertical (as Pillow), each stored as float32 (mode "F")."""
    t = (a.astype(np.float64) @ _pillow_matrix(a.shape[1], w).T).astype(np.float32)
    return (_pillow_matrix(a.shape[0], h) @ t.astype(np.float64)).astype(np.float32)


def _image(h=37, w=50, seed=0, dataset="Middlebury"):
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:h, :w]
    depth = (60 + 0.8 * xx + 40 * (yy > h // 2) + rng.normal(0, 1, (h, w))).astype(np.float32)
    rgb = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    return GDSRImage(dataset=dataset, name=f"{dataset}_t{seed}", index=f"t{seed}", depth=depth, rgb=rgb,
                     units="grey levels")


# ---------------------------------------------------------------- degradation


def test_crop_and_downsample_shapes():
    s = degrade(_image(37, 50), 8)
    assert s["gt"].shape == (1, 1, 32, 48) and s["lr"].shape == (1, 1, 4, 6) and s["rgb"].shape == (1, 3, 32, 48)
    assert s["factor"] == 8 and s["model_lr"] is s["lr"]
    assert torch.equal(s["gt"][0, 0], torch.from_numpy(_image(37, 50).depth[:32, :48]))  # bottom/right crop
    assert crop_to_multiple(np.zeros((5, 17, 33)), 16).shape == (5, 16, 32)
    assert bicubic(s["lr"], (32, 48)).shape == (1, 1, 32, 48)


@pytest.mark.parametrize("shape,size", [((37, 52), (9, 13)), ((16, 24), (2, 3)), ((9, 13), (36, 52)),
                                        ((6, 7), (96, 112))])
def test_resize_is_pillows_bicubic(shape, size):
    a = np.random.default_rng(1).uniform(0, 255, shape).astype(np.float32)
    ours = resize_pillow(torch.from_numpy(a)[None, None], size)[0, 0].numpy()
    np.testing.assert_allclose(ours, _pillow_resize(a, *size), atol=2e-4, rtol=0)
    plain = torch.nn.functional.interpolate(torch.from_numpy(a)[None, None], size=size, mode="bicubic")[0, 0]
    assert np.abs(plain.numpy() - _pillow_resize(a, *size)).max() > 1e-2  # torch's plain bicubic is not Pillow's


def test_resize_matches_pillow_itself():
    Image = pytest.importorskip("PIL.Image")
    a = np.random.default_rng(2).uniform(0, 255, (40, 56)).astype(np.float32)
    for h, w in ((10, 14), (160, 224)):
        ref = np.asarray(Image.fromarray(a, mode="F").resize((w, h), Image.BICUBIC))
        np.testing.assert_allclose(resize_pillow(torch.from_numpy(a)[None, None], (h, w))[0, 0].numpy(), ref,
                                   atol=2e-4)


def test_noise_is_seeded_and_scaled():
    img = _image(160, 192)
    a, b = degrade(img, 4, 5.0), degrade(img, 4, 5.0)
    clean = degrade(img, 4, 0.0)
    assert torch.equal(a["lr"], b["lr"]) and not torch.equal(a["lr"], clean["lr"])
    rng = float(clean["gt"].max() - clean["gt"].min())
    std = float((a["lr"] - clean["lr"]).std())
    assert abs(std - 5 * rng / 255) < 0.1 * 5 * rng / 255
    other = degrade(_image(160, 192, seed=0, dataset="Lu"), 4, 5.0)  # another image name: other draws
    assert not torch.allclose(other["lr"] - clean["lr"], a["lr"] - clean["lr"])
    assert torch.equal(degrade(img, 8, 5.0)["lr"], degrade(img, 8, 5.0)["lr"])
    z = torch.zeros(1, 1, 4, 4)
    assert torch.equal(add_noise(z, 0.0, 100.0, "x"), z)


def test_real_scene_input_is_the_real_depth():
    img = _image(48, 64, dataset="RGBDD_Test_Realscene")
    img.depth_lr = np.full((18, 24), 1.5, np.float32)  # 8/3 smaller, like 192x144 for 512x384
    s = degrade(img, 16)  # the real scene always runs at its own factor 4
    assert s["factor"] == 4 and s["lr"].shape == (1, 1, 18, 24) and s["model_lr"].shape == (1, 1, 12, 16)
    assert torch.allclose(s["model_lr"], torch.full((1, 1, 12, 16), 1.5))


# ---------------------------------------------------------------- RMSE conventions


def test_rmse_conventions():
    gt = torch.full((1, 1, 20, 20), 250.0)
    assert rmse(gt + 10, gt, "Middlebury") == pytest.approx(5.0)  # 260 -> 255
    assert rmse(torch.full_like(gt, 300.0), torch.full_like(gt, 255.0), "Lu") == 0.0  # both clipped
    m = torch.full((1, 1, 20, 20), 2.0)
    border = m.clone()
    border[..., :6, :] += 1.0
    border[..., :, -6:] -= 1.0
    assert rmse(border, m, "NYUDepthv2_Test") == 0.0  # a 6-pixel border does not count
    assert rmse(m + 0.01, m, "NYUDepthv2_Test") == pytest.approx(1.0)  # metres -> cm
    assert rmse(border, m, "RGBDD") > 0  # no crop
    assert rmse(m + 0.02, m, "RGBDD_Test_Realscene") == pytest.approx(2.0)
    with pytest.raises(ValueError):
        rmse(m, m, "KITTI")


# ---------------------------------------------------------------- readers (shared data)

EXPECTED = {  # count, (H, W) of the first file, value range in the protocol's units
    "Middlebury": (20, (370, 463), (0, 255)),
    "Lu": (6, (480, 640), (0, 255)),
    "NYUDepthv2_Test": (3, (480, 640), (0.3, 10.0)),
    "RGBDD": (405, (384, 512), (0.0, 5.0)),
    "RGBDD_Test_Realscene": (3, (384, 512), (0.0, 5.0)),
}


@pytest.mark.parametrize("dataset", SETS)
def test_readers(dataset):
    root = require_data_root(f"guided_dsr_testsets_dctnet/{dataset}")
    count, shape, (lo, hi) = EXPECTED[dataset]
    assert len(list_names(root, dataset)) == count
    img = next(gdsr_images(root, dataset, max_images=1))
    assert img.depth.dtype == np.float32 and img.depth.shape == shape
    assert img.rgb.dtype == np.uint8 and img.rgb.shape == shape + (3,)
    assert lo <= img.depth.min() < img.depth.max() <= hi
    if dataset in ("Middlebury", "Lu"):
        assert img.depth.max() > 100  # grey levels, not normalised
    if dataset == "RGBDD_Test_Realscene":
        assert img.depth_lr.shape == (144, 192) and 0.5 < img.depth_lr.min() < img.depth_lr.max() < 3.0  # metres
    else:
        assert img.depth_lr is None


def test_middlebury_split():
    root = require_data_root("guided_dsr_testsets_dctnet/Middlebury")
    imgs = {i.index: i for i in gdsr_images(root, "Middlebury", only=["02", "03"])}
    assert imgs["02"].scene == "Art" and imgs["02"].heldout
    assert imgs["03"].scene == "Baby1" and not imgs["03"].heldout
    assert len(FITTING) == 11 and len(set(list_names(root, "Middlebury")) - FITTING) == 9
    assert resolve_set("nyu") == "NYUDepthv2_Test"


def test_bicubic_reproduces_an_independent_computation():
    """Two held-out Middlebury images (Art, Venus) at x4: the track's bicubic RMSE equals the one computed here
    with the NumPy Pillow resampling (the protocol of DCTNet's processing scripts)."""
    root = require_data_root("guided_dsr_testsets_dctnet/Middlebury")
    for img in gdsr_images(root, "Middlebury", only=["02", "30"]):
        gt = img.depth[: img.depth.shape[0] // 4 * 4, : img.depth.shape[1] // 4 * 4]
        h, w = gt.shape
        lr = _pillow_resize(gt, h // 4, w // 4)
        lo, hi = gt.min(), gt.max()
        up = _pillow_resize((lr - lo) / (hi - lo), h, w) * (hi - lo) + lo  # DCTNet resizes the normalised map
        ref = float(np.sqrt(np.mean((np.clip(up, 0, 255).astype(np.float64) - np.clip(gt, 0, 255)) ** 2)))
        s = degrade(img, 4)
        assert rmse(bicubic(s["lr"], (h, w)), s["gt"], "Middlebury") == pytest.approx(ref, abs=2e-4)
        assert ref == pytest.approx({"02": 4.5675, "30": 1.9704}[img.index], abs=1e-3)


# ---------------------------------------------------------------- the command


def test_models_run_on_the_protocols_input():
    """``full`` on a small synthetic sample: output on the ground truth's grid, finite, and the
    ``--config`` overrides reach ``full`` on top of the bicubic K."""
    img = _image(64, 64)
    img.depth[:8, :8] = 0.0  # a dark corner: bicubic overshoot below 0 is missing for the model
    s = degrade(img, 4, 5.0)
    full = make_model("full", 4, {"num_layers": 2, "block_matching": {"match_layers": [1]}})
    assert full.config.degradation == "bicubic" and full.config.num_layers == 2
    assert full.config.block_matching.match_layers == (1,)
    out = _run_model(full, s, "cpu")
    assert out.shape == s["gt"].shape and torch.isfinite(out).all()
    assert make_model("trained-x4", 4) is not None  # upsample-x4 ships
    assert make_model("trained-x4", 16) is None  # nothing ships for x16
    assert all(make_model("trained", s).refiner is not None for s in (4, 16))  # "upsample": one for every factor
    assert make_model("trained-x4-refined", 4).refiner is not None and make_model("trained-x4-refined", 8) is None


def test_cli_rows(tmp_path, capsys, monkeypatch):
    """The command's rows and summary on one small image at x16. The model's forward is replaced by bicubic
    here (it is exercised above); everything else is the command as it runs."""
    import torch_depth_sr.evaluation.gdsr as track

    require_data_root("guided_dsr_testsets_dctnet/Middlebury")
    monkeypatch.setattr(track, "_run_model", lambda model, s, device: bicubic(s["model_lr"], s["gt"].shape[-2:]) + 0.5)
    out = tmp_path / "g.json"
    assert main(["bench", "--track", "gdsr", "--sets", "Middlebury", "--scenes", "30", "--scales", "16",
                 "--noise", "0", "5", "--methods", "bicubic", "full", "trained-x4", "--json", str(out),
                 "--config", '{"num_layers": 2, "block_matching": {"match_layers": [1]}}']) == 0
    data = json.loads(out.read_text())
    rows = data["results"]
    assert len(rows) == 6
    for r in rows:
        assert {"dataset", "scale", "noise", "method", "rmse", "image", "heldout"} <= set(r)
        assert r["dataset"] == "Middlebury" and r["scale"] == 16 and r["image"] == "Middlebury_30" and r["heldout"]
    trained = [r for r in rows if r["method"] == "trained-x4"]
    assert all(r["rmse"] is None and r["available"] is False for r in trained)  # no shipped upsample-x16 model
    ok = {(r["method"], r["noise"]): r["rmse"] for r in rows if r["rmse"] is not None}
    assert set(ok) == {("bicubic", 0.0), ("bicubic", 5.0), ("full", 0.0), ("full", 5.0)}
    assert all(0 < v < 20 for v in ok.values())
    assert {(r["subset"], r["method"]) for r in data["summary"]} >= {("all", "full"), ("heldout", "bicubic")}
    assert data["metadata"]["full_config"] == {"degradation": "bicubic", "num_layers": 2,
                                               "block_matching": {"match_layers": [1]}}
    assert "track gdsr" in capsys.readouterr().out


def test_cli_without_data(tmp_path, capsys):
    assert main(["bench", "--track", "gdsr", "--data", str(tmp_path), "--methods", "bicubic"]) == 2
    err = capsys.readouterr().err
    assert "not found" in err and "TORCH_DEPTH_SR_DATA" in err
    assert main(["bench", "--track", "gdsr", "--data", str(tmp_path), "--methods", "nope"]) == 2
