"""Readers of the shared benchmark data, IO round trips and scene discovery."""

import os

import cv2
import numpy as np
import pytest
import torch

from torch_depth_sr._data_root import ENV_VAR, data_root, require_data_root
from torch_depth_sr.datasets import (
    DataFileError,
    MiddleburyStereo,
    MissingDataFileError,
    NoisyMiddleburyUpsampling,
    RealSensorFrames,
    find_scenes,
    load_middlebury_scene,
    read_pfm,
    read_png_depth,
    read_rgb,
    write_pfm,
    write_png_depth,
)
from torch_depth_sr.datasets.io import decode_sun_depth, read_depth, read_npy, read_pgm16, write_npy
from torch_depth_sr.errors import DepthSRError

SAMPLE_KEYS = {"depth", "rgb", "gt", "mask", "scale", "name", "dataset"}


def _check_sample(s, with_gt=True):
    assert s["rgb"].dtype == torch.float32 and s["rgb"].shape[0] == 3
    assert 0.0 <= float(s["rgb"].min()) and float(s["rgb"].max()) <= 1.0
    assert s["depth"].dtype == torch.float32 and s["depth"].dim() == 3 and s["depth"].shape[0] == 1
    if with_gt:
        assert SAMPLE_KEYS <= set(s)
        assert s["gt"].shape == (1,) + tuple(s["rgb"].shape[1:])
        assert torch.equal(s["mask"], (s["gt"] > 0).float())
        assert torch.isfinite(s["gt"]).all()


# ----------------------------------------------------------------------------- IO (no data needed)
class TestIO:
    def test_pfm_round_trip(self, tmp_path):
        a = np.random.default_rng(0).normal(size=(7, 5)).astype(np.float32)
        a[0, 0] = np.inf
        write_pfm(tmp_path / "a.pfm", a)
        b, scale = read_pfm(tmp_path / "a.pfm", return_scale=True)
        np.testing.assert_array_equal(a, b)
        assert scale == 1.0
        raw = (tmp_path / "a.pfm").read_bytes()
        assert raw.startswith(b"Pf\n5 7\n-1\n")
        # rows bottom-up: the first stored row is the image's last row
        first = np.frombuffer(raw[len(b"Pf\n5 7\n-1\n"):][:20], "<f4")
        np.testing.assert_array_equal(first, a[-1])

    def test_pfm_colour_and_big_endian(self, tmp_path):
        a = np.arange(24, dtype=np.float32).reshape(2, 4, 3)
        write_pfm(tmp_path / "c.pfm", a)
        np.testing.assert_array_equal(read_pfm(tmp_path / "c.pfm"), a)
        g = np.arange(6, dtype=np.float32).reshape(2, 3)
        (tmp_path / "be.pfm").write_bytes(b"Pf\n3 2\n1.0\n" + g[::-1].astype(">f4").tobytes())
        np.testing.assert_array_equal(read_pfm(tmp_path / "be.pfm"), g)

    def test_pfm_errors(self, tmp_path):
        (tmp_path / "bad.pfm").write_bytes(b"P6\n1 1\n")
        with pytest.raises(DataFileError, match="not a PFM"):
            read_pfm(tmp_path / "bad.pfm")
        (tmp_path / "short.pfm").write_bytes(b"Pf\n3 2\n-1.0\n" + b"\0" * 8)
        with pytest.raises(DataFileError, match="truncated"):
            read_pfm(tmp_path / "short.pfm")
        with pytest.raises(MissingDataFileError, match="nope.pfm"):
            read_pfm(tmp_path / "nope.pfm")

    @pytest.mark.parametrize("bits", [8, 16])
    def test_png_round_trip(self, tmp_path, bits):
        a = np.random.default_rng(1).integers(0, 2**bits, size=(6, 9)).astype(np.float32)
        write_png_depth(tmp_path / "d.png", a, bits=bits)
        np.testing.assert_array_equal(read_png_depth(tmp_path / "d.png"), a)
        np.testing.assert_array_equal(read_depth(tmp_path / "d.png"), a)

    def test_npy_round_trip(self, tmp_path):
        a = np.random.default_rng(2).random((4, 5)).astype(np.float32)
        write_npy(tmp_path / "d.npy", a)
        np.testing.assert_array_equal(read_npy(tmp_path / "d.npy"), a)

    def test_corrupt_and_missing_images(self, tmp_path):
        (tmp_path / "x.png").write_bytes(b"not a png at all")
        with pytest.raises(DataFileError, match="x.png"):
            read_rgb(tmp_path / "x.png")
        with pytest.raises(MissingDataFileError, match="missing.png"):
            read_png_depth(tmp_path / "missing.png")
        assert issubclass(MissingDataFileError, FileNotFoundError)
        assert issubclass(DataFileError, DepthSRError)

    def test_colour_depth_rejected(self, tmp_path):
        img = np.zeros((4, 4, 3), np.uint8)
        img[..., 2] = 9
        cv2.imwrite(str(tmp_path / "c.png"), img)
        with pytest.raises(DataFileError, match="single-channel"):
            read_png_depth(tmp_path / "c.png")

    def test_rgb_order_and_range(self, tmp_path):
        img = np.zeros((2, 2, 3), np.uint8)
        img[..., 2] = 255  # BGR: red
        cv2.imwrite(str(tmp_path / "r.png"), img)
        rgb = read_rgb(tmp_path / "r.png")
        assert rgb.dtype == np.float32 and rgb.shape == (2, 2, 3)
        np.testing.assert_array_equal(rgb[0, 0], [1.0, 0.0, 0.0])

    def test_pgm16_little_endian(self, tmp_path):
        a = np.array([[839, 2047], [1000, 4]], np.uint16)
        (tmp_path / "d.pgm").write_bytes(b"P5 2 2 65535\n" + a.astype("<u2").tobytes())
        np.testing.assert_array_equal(read_pgm16(tmp_path / "d.pgm"), a)

    def test_sun_shift(self):
        mm = np.array([0, 1057, 9870], np.uint32)
        stored = ((mm << 3) | (mm >> 13)) & 0xFFFF
        np.testing.assert_array_equal(decode_sun_depth(stored), mm.astype(np.float32))


def test_data_root_env(monkeypatch, tmp_path):
    monkeypatch.setenv(ENV_VAR, str(tmp_path))
    assert data_root() == tmp_path
    monkeypatch.delenv(ENV_VAR)
    assert data_root().parts[-2:] == ("shared", "data")


# ----------------------------------------------------------------------------- real data
@pytest.fixture(scope="module")
def root():
    return require_data_root()


class TestMiddlebury:
    def test_all_years(self, root):
        ds = MiddleburyStereo(root)
        assert len(ds) == 21
        scales = {2001: {"Tsukuba": 16.0, "Venus": 8.0}, 2003: 4.0, 2005: 3.0, 2006: 3.0}
        for (year, d) in ds.items:
            want = scales[year][d.name] if year == 2001 else scales[year]
            assert load_middlebury_scene(d)["scale"] == want, d

    def test_art_2005(self, root):
        s = MiddleburyStereo(root, years=(2005,), scenes=["Art"])[0]
        _check_sample(s)
        assert s["gt"].shape == (1, 370, 463) and s["name"] == "Art" and s["dataset"] == "middlebury2005"
        assert float(s["gt"].max()) == 224.0
        assert float(s["gt"][s["gt"] > 0].min()) == 73.0
        assert abs(1 - float(s["mask"].mean()) - 0.0012) < 0.0005
        assert torch.equal(s["depth"], s["gt"])

    def test_tsukuba_palette_grey_values(self, root):
        s = load_middlebury_scene(root / "middlebury2001" / "Tsukuba")
        _check_sample(s)
        vals = set(torch.unique(s["gt"]).tolist())
        assert vals <= {0.0} | set(range(80, 225, 16)) and 0.0 in vals and 224.0 in vals
        assert s["scale"] == 16.0 and s["gt"].shape == (1, 288, 384)
        # the unknown pixels are the 18-px border
        assert float(s["mask"][0, 18:-18, 18:-18].min()) == 1.0

    def test_venus_cones(self, root):
        v = load_middlebury_scene(root / "middlebury2001" / "Venus")
        assert v["scale"] == 8.0 and float(v["mask"].min()) == 1.0
        c = load_middlebury_scene(root / "middlebury2003" / "Cones")
        _check_sample(c)
        assert c["scale"] == 4.0 and c["gt"].shape == (1, 375, 450) and float(c["gt"].max()) == 220.0

    def test_artl_pfm_flip_and_scale(self, root):
        s = load_middlebury_scene(root / "middlebury_eval3_half" / "ArtL")
        _check_sample(s)
        assert s["gt"].shape == (1, 554, 694) and s["scale"] == 1.0 and s["dataset"] == "middlebury_eval3_half"
        g = s["gt"][0].numpy()
        assert 37.9 < g[g > 0].min() and g.max() < 111.1
        assert abs((g == 0).mean() - 0.0023) < 0.001
        # orientation: compare with the 2005 third-size Art GT (x3 scaled) resized to this size
        a = load_middlebury_scene(root / "middlebury2005" / "Art")["gt"][0].numpy()
        a = cv2.resize(a, (694, 554), interpolation=cv2.INTER_NEAREST)
        m = (a > 0) & (g > 0)
        upright = np.corrcoef(g[m], a[m])[0, 1]
        flipped = g[::-1]
        mf = (a > 0) & (flipped > 0)
        wrong = np.corrcoef(flipped[mf], a[mf])[0, 1]
        assert upright > 0.9 and upright > wrong + 0.3
        # units: the PFM holds half-size px; the 2005 third-size file holds full-size px (x3) -> ratio 2
        ratio = np.median(a[m] / g[m])
        assert 1.8 < ratio < 2.2

    def test_missing_root_message(self, tmp_path):
        with pytest.raises(DepthSRError, match="no Middlebury scenes"):
            MiddleburyStereo(tmp_path)
        with pytest.raises(DepthSRError, match="year"):
            MiddleburyStereo(tmp_path, years=(1999,))


class TestNoisyMiddlebury:
    @pytest.mark.parametrize("variant,n", [("park2011", 6), ("ferstl2013", 3)])
    def test_layouts(self, root, variant, n):
        ds = NoisyMiddleburyUpsampling(root, variant=variant, factor=16)
        assert len(ds) == n
        s = ds[0]
        _check_sample(s)
        assert s["name"] == "art" and s["factor"] == 16 and s["scale"] == 1.0
        H, W = s["gt"].shape[1:]
        assert (H, W) == (1088, 1376) and s["depth"].shape == (1, H // 16, W // 16)
        assert float(s["gt"].min()) == 66.0 and float(s["gt"].max()) == 217.0

    def test_factors(self, root):
        folder = root / "noisy_middlebury_park2011"
        for f in (2, 4, 8):
            s = NoisyMiddleburyUpsampling(folder, "park2011", f, scenes=["laundry"])[0]
            assert s["depth"].shape == (1, 1088 // f, 1328 // f)
        with pytest.raises(DepthSRError, match="factor"):
            NoisyMiddleburyUpsampling(root, "park2011", 3)
        with pytest.raises(DepthSRError, match="variant"):
            NoisyMiddleburyUpsampling(root, "park", 2)


class TestRealSensor:
    def test_frames(self, root):
        ds = RealSensorFrames(root)
        assert [n for n, _ in ds.frames] == ["TUM", "SUN"]
        tum, sun = ds[0], ds[1]
        for s in (tum, sun):
            _check_sample(s, with_gt=False)
            assert "gt" not in s and s["units"] == "m" and s["registered"]
        d = tum["depth"][tum["depth"] > 0]
        assert 1.45 < float(d.min()) and float(d.max()) < 9.34
        assert abs(float((tum["depth"] == 0).float().mean()) - 0.1919) < 0.002
        d = sun["depth"][sun["depth"] > 0]
        assert abs(float(d.min()) - 1.057) < 1e-4 and abs(float(d.max()) - 9.870) < 1e-4

    def test_nyu_raw(self, root):
        ds = RealSensorFrames(root, include_unregistered=True)
        s = ds[2]
        assert s["name"] == "NYU_raw" and not s["registered"]
        d = s["depth"][s["depth"] > 0]
        assert 1.38 < float(d.min()) < 1.40 and 6.6 < float(d.max()) < 6.7
        assert abs(float((s["depth"] == 0).float().mean()) - 0.0723) < 0.002


class TestDiscover:
    def test_tracks_on_data_root(self, root):
        paper = find_scenes(root, "paper")
        assert len(paper) == 21 and [r.name for r in paper[:6]] == ["Art", "Books", "Dolls", "Laundry", "Moebius", "Reindeer"]
        assert {r.year for r in paper} == {2001, 2003, 2005, 2006}
        assert "ArtL" not in {r.name for r in paper}
        assert "ArtL" in {r.name for r in find_scenes(root, "sensor", include_eval3=True)}
        assert [r.name for r in find_scenes(root, "upsample-a")] == ["art", "books", "moebius"]
        assert len(find_scenes(root, "upsample-b")) == 6
        assert sorted(r.name for r in find_scenes(root, "real")) == ["SUN", "TUM"]
        rec = find_scenes(root, "upsample-b")[0]
        assert rec.load(factor=4)["depth"].shape[-1] == 1376 // 4

    def test_symlinked_2006_scene(self, root, tmp_path):
        scene = root / "middlebury2006" / "Baby1"
        (tmp_path / "middlebury2006").mkdir()
        os.symlink(scene, tmp_path / "middlebury2006" / "Baby1")
        for where in (tmp_path, tmp_path / "middlebury2006", tmp_path / "middlebury2006" / "Baby1"):
            recs = find_scenes(where, "paper")
            assert [(r.name, r.year) for r in recs] == [("Baby1", 2006)], where
            s = recs[0].load()
            assert s["scale"] == 3.0 and s["dataset"] == "middlebury2006"
        assert find_scenes(tmp_path, "upsample-b") == []

    def test_bad_args(self, tmp_path):
        with pytest.raises(DepthSRError, match="track"):
            find_scenes(tmp_path, "nope")
        with pytest.raises(DepthSRError, match="does not exist"):
            find_scenes(tmp_path / "absent", "paper")


def test_require_data_root_skips_with_message(monkeypatch, tmp_path):
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "absent"))
    with pytest.raises(pytest.skip.Exception, match=ENV_VAR):
        require_data_root()


def test_scene_records_pickle(tmp_path):
    import pickle

    root = require_data_root("middlebury2003")
    rec = find_scenes(root / "middlebury2003", "paper")[0]
    rec2 = pickle.loads(pickle.dumps(rec))
    assert rec2.name == "Cones" and rec2.load()["scale"] == 4.0
