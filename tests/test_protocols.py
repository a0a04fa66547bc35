"""Degradations of the `paper` and `sensor` tracks (shared/docs/benchmark.md)."""

import pickle

import numpy as np
import pytest
import torch

from torch_depth_sr._data_root import require_data_root
from torch_depth_sr.datasets import load_middlebury_scene, make_scene
from torch_depth_sr.errors import DepthSRError
from torch_depth_sr.evaluation import PaperDegradation, SensorDegradation, edge_band, make_degradation, stable_hash

REGIONS = ("holes", "edges", "flying", "impulse")


def _synthetic(name="scene_a", h=120, w=160):
    s = make_scene(h, w, seed=3)
    gt = s["gt"].clone()
    gt[:, :6, :] = 0  # some unknown pixels
    return {"gt": gt, "mask": (gt > 0).float(), "rgb": s["rgb"], "depth": gt.clone(), "name": name, "scale": 3.0}


@pytest.mark.parametrize("cls", [PaperDegradation, SensorDegradation])
class TestContract:
    def test_determinism(self, cls):
        s = _synthetic()
        a, b = cls(seed=7)(s), cls(seed=7)(s)
        for k in ("depth",) + REGIONS:
            assert torch.equal(a[k], b[k]), k
        c = cls(seed=7)(dict(s, name="scene_b"))
        d = cls(seed=8)(s)
        assert not torch.equal(a["depth"], c["depth"]) and not torch.equal(a["depth"], d["depth"])

    def test_keys_dtype_not_in_place(self, cls):
        s = _synthetic()
        before = {k: v.clone() for k, v in s.items() if torch.is_tensor(v)}
        out = cls()(s)
        for k, v in before.items():
            assert torch.equal(s[k], v), k
        assert out["depth"].dtype == torch.float32 and out["depth"].shape == s["gt"].shape
        for k in REGIONS:
            assert out[k].shape == s["gt"].shape and set(torch.unique(out[k]).tolist()) <= {0.0, 1.0}
        assert torch.equal(out["gt"], s["gt"]) and out["protocol"] in ("paper", "sensor")
        # unknown GT pixels are 0 in the input
        assert float(out["depth"][s["mask"] == 0].abs().max()) == 0.0

    def test_pickle(self, cls):
        t = cls(sigma=2.0, seed=3)
        t2 = pickle.loads(pickle.dumps(t))
        s = _synthetic()
        assert torch.equal(t(s)["depth"], t2(s)["depth"])

    def test_bad_sigma(self, cls):
        with pytest.raises(DepthSRError, match="sigma"):
            cls(sigma=-1.0)


def test_stable_hash_is_fixed():
    # sha256("Art")[:8] little-endian; must never change across machines or runs
    import hashlib

    assert stable_hash("Art") == int.from_bytes(hashlib.sha256(b"Art").digest()[:8], "little")
    assert stable_hash("Art") != stable_hash("Books")


def test_paper_noise_statistics_and_sweep():
    s = _synthetic(h=200, w=200)
    known = s["mask"][0] > 0
    for sigma in (0.0, 5.0, 10.0):
        out = PaperDegradation(sigma=sigma, seed=1)(s)
        r = (out["depth"] - s["gt"])[0][known]
        assert abs(float(r.std()) - sigma) < 0.05 * sigma + 1e-6
        assert abs(float(r.mean())) < 0.05 * sigma + 1e-6
    # a sweep reuses the same standard-normal draw
    a, b = PaperDegradation(5.0, seed=1)(s), PaperDegradation(10.0, seed=1)(s)
    torch.testing.assert_close(2 * (a["depth"] - s["gt"])[0][known], (b["depth"] - s["gt"])[0][known], atol=1e-4, rtol=0)
    assert torch.equal(a["holes"], 1 - s["mask"])


def test_edge_band_step():
    gt = np.full((40, 40), 100.0)
    gt[:, 20:] = 150.0
    band = edge_band(gt)
    cols = np.flatnonzero(band.any(0))
    # blurred step: |grad| > 4 on cols 18..21 (central differences), dilated by 2 px
    assert cols.min() >= 15 and cols.max() <= 24 and band[:, 19:21].all()
    assert not edge_band(np.full((20, 20), 100.0)).any()


def test_sensor_fractions_synthetic():
    s = _synthetic(h=240, w=320)
    out = SensorDegradation(seed=0)(s)
    _check_fractions(s, out)


def _check_fractions(s, out):
    known = s["mask"][0].numpy() > 0
    n = known.size
    band = out["edges"][0].numpy() > 0
    holes = out["holes"][0].numpy() > 0
    depth = out["depth"][0].numpy()
    assert band.sum() > 100
    assert np.array_equal(holes | ~known, depth == 0) or np.all(depth[holes] == 0)
    # holes in the band: the 30 % shadows plus dropouts and blobs falling there
    p_other = 0.03 + 0.04 - 0.03 * 0.04
    expect = 1 - 0.7 * (1 - p_other)
    frac = (holes & band).sum() / band.sum()
    assert abs(frac - expect) < 0.04, frac
    # flying pixels left: 30 % of the band minus those holed or overwritten by impulses
    flying_left = (out["flying"][0].numpy() > 0).sum() / band.sum()
    assert abs(flying_left - 0.3 * (1 - expect) * (1 - 0.005)) < 0.03, flying_left
    # impulses left: 0.5 % of all pixels minus the holed ones, among known pixels
    imp = (out["impulse"][0].numpy() > 0).sum() / n
    assert abs(imp - 0.005 * (1 - p_other) * known.mean()) < 0.0015, imp
    # total holes outside the band: dropouts + blobs (>= 4 %) among non-band known pixels
    off = known & ~band
    frac_off = holes[off].mean()
    assert 0.06 < frac_off < 0.085, frac_off


def test_sensor_flying_values_between_min_and_max():
    s = _synthetic(h=200, w=200)
    out = SensorDegradation(sigma=0.0, seed=2)(s)
    fly = out["flying"][0] > 0
    gt = s["gt"][0]
    pool = torch.nn.functional.max_pool2d
    nmax = pool(gt[None, None], 5, 1, 2)[0, 0]
    nmin = -pool(torch.where(gt > 0, -gt, torch.tensor(-1e9))[None, None], 5, 1, 2)[0, 0]
    d = out["depth"][0]
    assert fly.sum() > 50
    assert bool((d[fly] >= nmin[fly] - 1e-3).all() and (d[fly] <= nmax[fly] + 1e-3).all())
    # with sigma = 0 the untouched known pixels equal the GT
    clean = (s["mask"][0] > 0) & (out["holes"][0] == 0) & ~fly & (out["impulse"][0] == 0)
    assert torch.equal(d[clean], gt[clean]) or float((d[clean] - gt[clean]).abs().max()) == 0.0


def test_sensor_on_real_scene():
    root = require_data_root("middlebury2005")
    s = load_middlebury_scene(root / "middlebury2005" / "Art")
    out = make_degradation("sensor", seed=0)(s)
    _check_fractions(s, out)
    again = make_degradation("sensor", seed=0)(load_middlebury_scene(root / "middlebury2005" / "Art"))
    assert torch.equal(out["depth"], again["depth"])
    with pytest.raises(DepthSRError, match="track"):
        make_degradation("upsample-a")


def test_upsampling_metrics_also_score_the_output_as_an_8bit_png_stores_it():
    from torch_depth_sr.evaluation.bench import _metrics

    gt = torch.tensor([[[10.0, 20.0, 30.0, 40.0]]])
    pred = torch.tensor([[[[10.3, 19.6, 30.0, 41.4]]]])
    m = _metrics(pred, {"gt": gt}, "upsample-b")
    assert m["mae"] == pytest.approx((0.3 + 0.4 + 0 + 1.4) / 4)
    assert m["mae_8bit"] == pytest.approx(1 / 4)  # 10, 20, 30, 41 after rounding
    assert m["rmse_8bit"] == pytest.approx(0.5)
