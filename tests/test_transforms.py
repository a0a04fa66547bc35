"""Contract tests of torch_depth_sr.transforms (torchvision-v2 style)."""
import pickle

import numpy as np
import pytest
import torch

from torch_depth_sr.datasets.synthetic import make_scene
from torch_depth_sr.errors import DepthSRError, ShapeError
from torch_depth_sr.transforms import (
    AddFlyingPixels,
    AddGaussianNoise,
    AddHoles,
    AddImpulses,
    Compose,
    Downsample,
    RandomCrop,
    RestoreDepth,
)

TINY = dict(num_layers=2, block_matching={"search_window": 7, "k": 4})


@pytest.fixture(scope="module")
def sample():
    s = make_scene(48, 64, seed=5)
    return {"depth": s["gt"].clone(), "rgb": s["rgb"], "gt": s["gt"], "mask": s["mask"], "name": "scene5",
            "extra": "kept"}


def _degradations():
    return [AddGaussianNoise(5.0), AddGaussianNoise((2.0, 8.0)), AddHoles(), AddFlyingPixels(), AddImpulses(),
            RandomCrop(32), Downsample(2),
            Compose([RandomCrop(32), AddFlyingPixels(), AddImpulses(), AddGaussianNoise(5.0), AddHoles()])]


ALL = _degradations() + [RestoreDepth(**TINY)]
IDS = [repr(t).split("(")[0] + str(i) for i, t in enumerate(ALL)]


def _clone(s):
    return {k: (v.clone() if isinstance(v, torch.Tensor) else v) for k, v in s.items()}


def _equal(a, b):
    assert a.keys() == b.keys()
    for k in a:
        if isinstance(a[k], torch.Tensor):
            assert torch.equal(a[k], b[k]), k
        else:
            assert a[k] == b[k], k


@pytest.mark.parametrize("t", ALL, ids=IDS)
class TestContract:
    def test_smoke_and_passthrough(self, t, sample):
        out = t(sample)
        assert out is not sample
        assert out["extra"] == "kept" and out["name"] == "scene5"
        assert out["depth"].dim() == 3 and out["rgb"].shape[0] == 3

    def test_not_in_place(self, t, sample):
        before = _clone(sample)
        t(sample)
        _equal(sample, before)

    def test_dtype_kept(self, t, sample):
        s = dict(sample, depth=sample["depth"].double())
        assert t(s)["depth"].dtype == torch.float64
        s16 = dict(sample, depth=(sample["depth"] * 100).to(torch.int32))
        assert t(s16)["depth"].dtype == torch.int32

    def test_pickle(self, t, sample):
        t2 = pickle.loads(pickle.dumps(t))
        torch.manual_seed(3)
        a = t(sample)
        torch.manual_seed(3)
        b = t2(sample)
        _equal(a, b)

    def test_same_seed_same_sample(self, t, sample):
        torch.manual_seed(0)
        a = t(sample)
        torch.manual_seed(0)
        b = t(sample)
        _equal(a, b)

    def test_tuple_sample(self, t, sample):
        tup = (sample["depth"], sample["rgb"], sample["gt"], sample["mask"], "extra")
        out = t(tup)
        assert isinstance(out, tuple) and len(out) == 5 and out[4] == "extra"
        torch.manual_seed(1)
        d = t(sample)
        torch.manual_seed(1)
        o = t(tup)
        assert torch.equal(o[0], d["depth"]) and torch.equal(o[1], d["rgb"])


class TestRandomness:
    @pytest.mark.parametrize("t", _degradations()[:5], ids=lambda t: type(t).__name__)
    def test_explicit_seed_depends_on_sample_only(self, t, sample):
        t.seed = 7
        torch.manual_seed(0)
        a = t(sample)
        torch.manual_seed(1)  # the global generator is not used
        b = t(sample)
        _equal(a, b)
        c = t(dict(sample, name="other"))
        if not isinstance(t, RandomCrop):
            assert not torch.equal(a["depth"], c["depth"])

    def test_different_draws_differ(self, sample):
        t = AddHoles()
        assert not torch.equal(t(sample)["depth"], t(sample)["depth"])


class TestDegradations:
    def test_noise_only_on_measured(self, sample):
        d = sample["depth"].clone()
        d[:, :10] = 0
        out = AddGaussianNoise(5.0)(dict(sample, depth=d))["depth"]
        assert (out[:, :10] == 0).all() and (out[:, 10:] > 0).all()
        assert 3.5 < float((out[:, 10:] - d[:, 10:]).std()) < 6.5

    def test_holes_fraction(self, sample):
        out = AddHoles(dropout=0.1, blob_coverage=0.0, edge_fraction=0.0)(sample)["depth"]
        frac = float((out == 0).float().mean())
        assert abs(frac - 0.1) < 0.01

    def test_blob_coverage(self):
        d = torch.full((1, 128, 128), 50.0)
        out = AddHoles(dropout=0.0, blob_coverage=0.1, edge_fraction=0.0)(d)
        assert 0.04 < float((out == 0).float().mean()) < 0.2

    def test_edge_shadows_at_edges(self):
        d = torch.full((1, 40, 40), 50.0)
        d[:, :, 20:] = 150.0
        out = AddHoles(dropout=0.0, blob_coverage=0.0, edge_fraction=1.0)(d)
        cols = (out[0] == 0).any(0).nonzero().flatten()
        assert set(cols.tolist()) == {17, 18, 19, 20, 21, 22}

    def test_flying_between_neighbours(self):
        d = torch.full((1, 40, 40), 50.0)
        d[:, :, 20:] = 150.0
        out = AddFlyingPixels(fraction=1.0)(d)
        changed = out != d
        assert changed.any() and ((out >= 50) & (out <= 150)).all()

    def test_impulses_in_range(self, sample):
        out = AddImpulses(fraction=0.05)(sample)["depth"]
        changed = out != sample["depth"]
        assert 0.03 < float(changed.float().mean()) <= 0.051
        g = sample["gt"][sample["gt"] > 0]
        assert out.min() >= g.min() and out.max() <= g.max()

    def test_downsample_area_and_missing(self):
        d = torch.arange(16.0).reshape(1, 4, 4) + 1
        d[0, 0, 0] = 0
        out = Downsample(2)(d)
        assert out.shape == (1, 2, 2)
        assert torch.allclose(out[0, 0, 0], torch.tensor((2 + 5 + 6) / 3))
        with pytest.raises(DepthSRError, match="divisible"):
            Downsample(3)(d)

    def test_crop_alignment_and_low_res(self, sample):
        s = dict(sample, depth=Downsample(2)(sample)["depth"])
        torch.manual_seed(0)
        out = RandomCrop(16)(s)
        assert out["rgb"].shape[-2:] == (16, 16) and out["depth"].shape[-2:] == (8, 8)
        # the crop of the low-res depth is the low-res depth of the crop of gt
        assert torch.allclose(Downsample(2)({"depth": out["gt"]})["depth"], out["depth"])

    def test_crop_too_large(self, sample):
        with pytest.raises(DepthSRError, match="larger than the sample"):
            RandomCrop(100)(sample)

    def test_batched(self, sample):
        b = {k: (v[None].repeat(2, 1, 1, 1) if isinstance(v, torch.Tensor) else v) for k, v in sample.items()}
        out = Compose([RandomCrop(32), AddGaussianNoise(3.0), AddHoles()])(b)
        assert out["depth"].shape == (2, 1, 32, 32) and out["rgb"].shape == (2, 3, 32, 32)

    def test_numpy_uint16(self, sample):
        d = (sample["gt"][0].numpy() * 100).astype(np.uint16)
        out = Compose([AddGaussianNoise(100.0), AddHoles()])(d)
        assert isinstance(out, np.ndarray) and out.dtype == np.uint16 and out.shape == d.shape

    def test_bad_arguments(self):
        with pytest.raises(DepthSRError, match="sigma"):
            AddGaussianNoise(-1.0)
        with pytest.raises(DepthSRError, match=r"\[0, 1\]"):
            AddHoles(dropout=2.0)
        with pytest.raises(DepthSRError, match="dict, tuple"):
            AddHoles()("not a sample")


class TestRestoreDepth:
    def test_improves_and_keeps_layout(self, sample):
        torch.manual_seed(0)
        noisy = Compose([AddGaussianNoise(5.0), AddHoles()])(sample)
        out = RestoreDepth(keep_input="raw_depth", **TINY)(noisy)
        assert out["depth"].shape == noisy["depth"].shape and torch.equal(out["raw_depth"], noisy["depth"])
        valid = sample["mask"] > 0
        err_in = (noisy["depth"] - sample["gt"])[valid & (noisy["depth"] > 0)].pow(2).mean().sqrt()
        err_out = (out["depth"] - sample["gt"])[valid].pow(2).mean().sqrt()
        assert err_out < err_in

    def test_batched_equals_per_sample(self, sample):
        t = RestoreDepth(**TINY)
        torch.manual_seed(0)
        a = AddGaussianNoise(5.0)(sample)
        b = AddGaussianNoise(5.0)(sample)
        batch = {"depth": torch.stack([a["depth"], b["depth"]]), "rgb": torch.stack([a["rgb"], b["rgb"]])}
        out = t(batch)["depth"]
        assert out.shape == (2, 1, 48, 64)
        assert torch.allclose(out[0], t(a)["depth"], atol=1e-3)
        assert torch.allclose(out[1], t(b)["depth"], atol=1e-3)

    def test_guided_upsampling_and_confidence(self, sample):
        s = Downsample(2)(sample)
        out = RestoreDepth(with_confidence=True, **TINY)(s)
        assert out["depth"].shape == (1, 48, 64) and "confidence" in out

    def test_no_grad_and_frozen(self, sample):
        t = RestoreDepth(**TINY)
        assert not any(p.requires_grad for p in t.restorer.parameters())
        assert not t(sample)["depth"].requires_grad

    def test_rejects_non_restorer(self):
        with pytest.raises(DepthSRError, match="DepthRestorer"):
            RestoreDepth(restorer=torch.nn.Identity())


class TestOddInputs:
    """Issue 26 item 10: no raw error from a transform; big-endian numpy gives the native result."""

    @pytest.mark.parametrize("shape", [(), (8,), (0, 8), (1, 8, 0)])
    @pytest.mark.parametrize("t", ALL, ids=IDS)
    def test_depth_without_a_grid_is_a_shape_error(self, t, shape):
        for sample in (torch.full(shape, 5.0), np.full(shape, 5, np.uint16), {"depth": torch.full(shape, 5.0)}):
            with pytest.raises(ShapeError) as info:
                t(sample)
            actual, grid = tuple(info.value.actual), shape[-2:]
            assert actual[len(actual) - len(grid):] == grid, actual

    @pytest.mark.parametrize("shape", [(), (48,)])
    @pytest.mark.parametrize("key", ["depth", "gt", "mask", "rgb"])
    def test_crop_refuses_an_entry_without_two_dims(self, sample, key, shape):
        with pytest.raises(ShapeError, match=rf"RandomCrop.*sample\['{key}'\] has shape \({'48,' if shape else ''}\)"
                           ) as info:
            RandomCrop(16)(dict(sample, **{key: torch.ones(shape)}))
        assert info.value.actual == shape and "H,W" in info.value.expected
        out = RandomCrop(16)(dict(sample, scale=torch.tensor(2.0), per_row=torch.ones(48)))  # extras pass through
        assert out["scale"].shape == () and out["per_row"].shape == (48,)

    def test_crop_cuts_numpy_colour_in_its_first_two_dims(self, sample):
        hwc = sample["rgb"].permute(1, 2, 0).numpy()
        out = RandomCrop((16, 24), seed=1)(dict(sample, rgb=hwc))
        ref = RandomCrop((16, 24), seed=1)(sample)
        assert out["rgb"].shape == (16, 24, 3)
        np.testing.assert_array_equal(out["rgb"], ref["rgb"].permute(1, 2, 0).numpy())
        assert torch.equal(out["depth"], ref["depth"])

    def test_crop_larger_than_the_sample_is_a_shape_error(self, sample):
        with pytest.raises(ShapeError, match="larger than the sample 48x64") as info:
            RandomCrop((50, 10))(sample)
        assert info.value.actual == (48, 64)

    @pytest.mark.parametrize("t", ALL, ids=IDS)
    def test_5d_depth_is_transformed_or_a_shape_error(self, t, sample):
        d = sample["gt"][None, None].repeat(1, 2, 1, 1, 1)  # (1, 2, 1, 48, 64)
        if isinstance(t, RestoreDepth):
            with pytest.raises(ShapeError, match="got shape \\(1, 2, 1, 48, 64\\)"):
                t({"depth": d})
            return
        out = t({"depth": d, "name": "a"})["depth"]
        assert out.shape[:3] == (1, 2, 1)

    @pytest.mark.parametrize("dtype", [">f4", ">u2"])
    @pytest.mark.parametrize("t", _degradations() + [Compose([RandomCrop(32), RestoreDepth(**TINY)])],
                             ids=IDS[:-1] + ["Restore"])
    def test_big_endian_numpy_gives_the_native_result(self, t, dtype, sample):
        d = (sample["gt"][0].numpy() * 10).astype(dtype)
        rgb = (sample["rgb"].permute(1, 2, 0).numpy() * 255).round().astype(">u2") * 257  # 16-bit H×W×3
        mask = sample["mask"][0].numpy().astype(">f4")
        seeded = [x for x in getattr(t, "transforms", [t]) if hasattr(x, "seed")]
        for x in seeded:
            x.seed = 3
        big = t({"depth": d, "rgb": rgb, "mask": mask, "name": "a"})
        nat = t({"depth": d.astype(np.dtype(dtype).newbyteorder("=")), "rgb": rgb.astype(np.uint16),
                 "mask": mask.astype(np.float32), "name": "a"})
        assert big["depth"].dtype == np.dtype(dtype).newbyteorder("=") and big["depth"].dtype.isnative
        np.testing.assert_array_equal(big["depth"], nat["depth"])

    def test_restore_depth_reads_16_bit_colour(self, sample):
        t = RestoreDepth(**TINY)
        d = sample["gt"][0].numpy()
        rgb8 = (sample["rgb"].permute(1, 2, 0).numpy() * 255).round().astype(np.uint8)
        out8 = t({"depth": d, "rgb": rgb8})["depth"]
        out16 = t({"depth": d, "rgb": rgb8.astype(np.uint16) * 257})["depth"]  # was read as 257x too bright
        np.testing.assert_allclose(out16, out8, atol=1e-4)

