"""Tests on the shared benchmark data (skipped with a message when ../shared/data is absent)."""
import os

import numpy as np
import pytest
import torch

from torch_depth_sr._data_root import require_data_root


@pytest.fixture(scope="module")
def root():
    return require_data_root()


def _scene(root, track, name):
    from torch_depth_sr.datasets.discover import find_scenes

    recs = [r for r in find_scenes(root, track) if r.name == name]
    assert recs, f"scene {name} not found under {root}"
    return recs[0]


class TestReaders:
    def test_paper_track_finds_21_scenes(self, root):
        from torch_depth_sr.datasets.discover import find_scenes

        recs = find_scenes(root, "paper")
        assert len(recs) == 21
        assert {r.year for r in recs} == {2001, 2003, 2005, 2006}

    @pytest.mark.parametrize("name, scale, gt_max", [("Art", 3.0, 224), ("Cones", 4.0, 220), ("Tsukuba", 16.0, 224),
                                                     ("Venus", 8.0, 158)])
    def test_scale_factors_and_values(self, root, name, scale, gt_max):
        s = _scene(root, "paper", name).load()
        assert s["scale"] == scale
        assert float(s["gt"].max()) == gt_max
        assert s["rgb"].shape[0] == 3 and s["rgb"].shape[1:] == s["gt"].shape[1:]
        assert float(s["rgb"].min()) >= 0 and float(s["rgb"].max()) <= 1

    def test_tsukuba_grey_levels_not_palette_indices(self, root):
        v = np.unique(_scene(root, "paper", "Tsukuba").load()["gt"].numpy())
        assert v.min() == 0 and set(v[v > 0]).issubset(set(range(80, 225)))

    def test_discover_on_a_folder_holding_only_one_2006_scene(self, root, tmp_path):
        from torch_depth_sr.datasets.discover import find_scenes

        (tmp_path / "middlebury2006").mkdir()
        os.symlink(root / "middlebury2006" / "Baby1", tmp_path / "middlebury2006" / "Baby1")
        assert [r.name for r in find_scenes(tmp_path, "paper")] == ["Baby1"]
        assert [r.name for r in find_scenes(tmp_path / "middlebury2006" / "Baby1", "paper")] == ["Baby1"]

    def test_upsampling_sets(self, root):
        from torch_depth_sr.datasets.discover import find_scenes

        assert len(find_scenes(root, "upsample-b")) == 6 and len(find_scenes(root, "upsample-a")) == 3
        s = find_scenes(root, "upsample-b")[0].load(factor=4)
        assert tuple(s["gt"].shape[-2:]) == tuple(4 * n for n in s["depth"].shape[-2:])


class TestProtocols:
    def test_same_seed_same_input_and_names_differ(self, root):
        from torch_depth_sr.degradations import make_degradation

        s = _scene(root, "paper", "Baby1").load()
        a, b = make_degradation("sensor")(s), make_degradation("sensor")(s)
        assert torch.equal(a["depth"], b["depth"])
        other = dict(s, name="Baby2")
        assert not torch.equal(a["depth"], make_degradation("sensor")(other)["depth"])

    def test_paper_noise_level(self, root):
        from torch_depth_sr.degradations import make_degradation

        s = _scene(root, "paper", "Cloth1").load()
        d = make_degradation("paper")(s)
        known = s["gt"] > 0
        assert abs(float((d["depth"] - s["gt"])[known].std()) - 5.0) < 0.1
        assert bool((d["depth"][~known] == 0).all())


@pytest.mark.parametrize("track", ["paper", "sensor"])
def test_full_beats_jbf_on_two_scenes(root, track):
    """Regression: the full model beats the tuned JBF on crops of two scenes never used for fitting."""
    from torch_depth_sr.evaluation.methods import run_method
    from torch_depth_sr.degradations import make_degradation
    from torch_depth_sr.metrics import rmse

    for name in ("Art", "Teddy"):
        s = make_degradation(track)(_scene(root, track, name).load())
        crop = {k: (v[..., 100:260, 100:260] if isinstance(v, torch.Tensor) and v.ndim == 3 else v) for k, v in s.items()}
        crop["depth"] = crop["depth"].clamp_min(0)
        errs = {m: float(rmse(run_method(m, crop), crop["gt"][None], crop["mask"][None])[0]) for m in ("jbf", "full")}
        assert errs["full"] < errs["jbf"], (track, name, errs)


class TestUpsamplingFittingSet:
    def test_seeded_area_downsampled_2006_only(self, root):
        from torch_depth_sr.evaluation.tune_upsampling import upsampling_fitting_samples

        a, b = upsampling_fitting_samples(), upsampling_fitting_samples()
        assert len(a) == 22 and {s["factor"] for s in a} == {2, 4}
        for s, t in zip(a, b):
            assert torch.equal(s["depth"], t["depth"])
            f = s["factor"]
            assert s["depth"].shape[-2:] == (s["gt"].shape[-2] // f, s["gt"].shape[-1] // f)
            assert s["depth"].min() >= 0 and s["depth"].max() <= 255 and torch.equal(s["depth"], s["depth"].round())
            # the input is the area average of the ground truth plus sigma = 5 noise, not point samples
            m = torch.nn.functional.avg_pool2d(s["mask"], f) == 1
            r = (s["depth"] - torch.nn.functional.avg_pool2d(s["gt"], f))[m]
            assert 4.5 < float(r.std()) < 5.5 and abs(float(r.mean())) < 0.2
