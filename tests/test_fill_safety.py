"""Holes at depth gaps are filled from one side, never bridged; ``fill="trusted"`` leaves doubtful ones missing."""
import math

import numpy as np
import pytest
import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.fill import fill_holes_sided
from torch_depth_sr.model import restore_depth

FG, BG, SIGMA = 60.0, 140.0, 2.0  # disparity-like values: the square in front, the wall behind


def _shadow_scene(h=64, w=80, seed=0, shadow=8):
    """A textured wall (BG) with a square (FG) in front, of a somewhat different colour; a sensor shadow
    ``shadow`` px wide to the right of the square, on the wall (it has the wall's colour)."""
    g = torch.Generator().manual_seed(seed)
    gt = torch.full((h, w), BG)
    rgb = torch.empty(3, h, w)
    rgb[0], rgb[1], rgb[2] = 0.45, 0.45, 0.5  # wall: grey
    rgb += 0.03 * torch.rand(3, h, w, generator=g)  # texture
    y0, y1, x0, x1 = 16, 48, 20, 44
    gt[y0:y1, x0:x1] = FG
    rgb[:, y0:y1, x0:x1] = torch.tensor([0.55, 0.45, 0.4])[:, None, None] + 0.03 * torch.rand(3, y1 - y0, x1 - x0,
                                                                                          generator=g)
    depth = gt + SIGMA * torch.randn(h, w, generator=g)
    hole = torch.zeros(h, w, dtype=torch.bool)
    hole[y0 - 2:y1 + 2, x1:x1 + shadow] = True  # shadow on the background side of the right edge
    hole[y0:y1, x0 - 1] = True  # a one-pixel gap on the left edge too
    depth[hole] = 0
    return depth, rgb.clamp(0, 1), gt, hole


def test_shadow_hole_is_filled_from_the_background_not_bridged():
    depth, rgb, gt, hole = _shadow_scene()
    out = DepthRestorer()(depth[None, None], rgb[None])[0, 0]
    v = out[hole]
    own = gt[hole]
    assert bool(torch.isfinite(v).all())
    between = (v > FG + 3 * SIGMA) & (v < BG - 3 * SIGMA)
    assert int(between.sum()) == 0, f"{int(between.sum())} of {v.numel()} shadow pixels bridge the gap: {v[between][:8]}"
    assert float((v - own).abs().max()) < 4 * SIGMA


def test_fill_holes_sided_takes_one_side_and_flags_a_tie():
    y = torch.zeros(1, 1, 12, 16)
    y[..., :, :7] = 10.0
    y[..., :, 9:] = 50.0  # columns 7, 8 missing
    rgb = torch.zeros(1, 3, 12, 16)
    rgb[:, :, :, 8:] = 1.0  # column 8 looks like the right side, column 7 like the left
    r = fill_holes_sided(y, (y > 0).float(), rgb, kernel_size=7, gap=4.0)
    assert torch.allclose(r.depth[0, 0, :, 7], torch.full((12,), 10.0))
    assert torch.allclose(r.depth[0, 0, :, 8], torch.full((12,), 50.0))
    assert bool((r.confident[0, 0, :, 7:9] == 1).all()) and bool((r.gap[0, 0, :, 7:9] == 1).all())
    # the same gap with one colour everywhere: no side is clear
    r2 = fill_holes_sided(y, (y > 0).float(), torch.zeros_like(rgb), kernel_size=7, gap=4.0)
    assert bool((r2.confident[0, 0, :, 7:9] == 0).any())
    assert bool((r2.confident[0, 0, :, :7] == 1).all())
    # a smooth surface with a hole is no gap: filled confidently, close to the surface
    ramp = torch.linspace(100, 101, 16).expand(1, 1, 12, 16).clone()
    m = torch.ones_like(ramp)
    m[..., 5:7, 6:9] = 0
    r3 = fill_holes_sided(ramp * m, m, torch.zeros_like(rgb), kernel_size=7, gap=4.0)
    assert bool((r3.confident == 1).all()) and float((r3.depth - ramp).abs().max()) < 0.5


def _ambiguous_step(h=48, w=64):
    """Two flat surfaces, one colour, a hole straddling the step: no side is clear."""
    d = np.full((h, w), 1000.0)
    d[:, w // 2:] = 3000.0
    hole = np.zeros((h, w), bool)
    hole[10:38, w // 2 - 3:w // 2 + 3] = True
    d[hole] = 0
    rgb = np.full((h, w, 3), 128, np.uint8)
    return d, rgb, hole


def test_trusted_leaves_ambiguous_holes_missing_float():
    d, rgb, hole = _ambiguous_step()
    res = restore_depth(d.astype(np.float32), rgb, fill="trusted", return_details=True)
    out, conf = res.depth, np.asarray(res.confidence)
    left = np.isnan(out)
    assert left.any(), "an ambiguous hole across a depth gap must be left missing with fill='trusted'"
    assert (left <= hole).all(), "only holes may be left missing"
    assert (conf[left] == 0).all()
    assert np.isfinite(out[~hole]).all()
    # what was filled is on one side or the other, not in between
    filled = hole & ~left
    assert not ((out[filled] > 1300) & (out[filled] < 2700)).any()
    # the default fills everything
    full = restore_depth(d.astype(np.float32), rgb)
    assert np.isfinite(full).all() and (full > 0).all()


def test_trusted_uint16_gives_zero_where_left_missing():
    d, rgb, hole = _ambiguous_step()
    out = restore_depth(d.astype(np.uint16), rgb, fill="trusted")
    assert out.dtype == np.uint16
    zero = out == 0
    assert zero.any() and (zero <= hole).all()
    assert (out[~hole] > 0).all()


def test_trusted_torch_float_batch_and_module():
    d, rgb, hole = _ambiguous_step()
    y = torch.from_numpy(d).float()[None, None].repeat(2, 1, 1, 1)
    c = torch.from_numpy(rgb).permute(2, 0, 1).float()[None].repeat(2, 1, 1, 1) / 255
    out = DepthRestorer()(y, c, fill="trusted")
    assert out.shape == y.shape and bool(torch.isnan(out).any())
    assert bool(torch.equal(torch.isnan(out[0]), torch.isnan(out[1])))


@pytest.mark.parametrize("bad", ["some", "", None, 1])
def test_fill_argument_is_checked(bad):
    d, rgb, _ = _ambiguous_step()
    with pytest.raises(ValueError, match="fill="):
        restore_depth(d.astype(np.float32), rgb, fill=bad)


def test_bridging_metric_on_a_synthetic_sample():
    from torch_depth_sr.evaluation.fill_safety import bridging

    gt = np.full((20, 20), 50.0)
    gt[:, 10:] = 100.0
    hole = np.zeros((20, 20), bool)
    hole[5:15, 9:11] = True
    sample = {"gt": torch.from_numpy(gt).float()[None], "mask": torch.ones(1, 20, 20),
              "holes": torch.from_numpy(hole).float()[None], "edges": torch.ones(1, 20, 20)}
    good = gt.copy()
    assert bridging(good, sample)["bridge"] == 0.0
    mixed = np.where(hole, 75.0, gt)
    assert bridging(mixed, sample)["bridge"] == 1.0
    swapped = np.where(hole, 150.0 - gt, gt)
    r = bridging(swapped, sample)
    assert r["bridge"] == 0.0 and r["wrong_side"] == 1.0 and not math.isnan(r["edge_off"])
