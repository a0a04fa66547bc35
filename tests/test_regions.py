"""Region labelling of the per-region error analysis (``evaluation/regions.py``) on synthetic maps, and its sums."""
from __future__ import annotations

import numpy as np
import pytest

from torch_depth_sr.evaluation.regions import REGIONS, label_regions, region_errors, summarise_regions

PLANAR, SLANTED, CURVED, EDGE, THIN = range(1, 6)
N = 64


def _grid():
    return np.meshgrid(np.arange(N, dtype=np.float64), np.arange(N, dtype=np.float64), indexing="xy")


def test_fronto_parallel_plane_is_planar():
    labels = label_regions(np.full((N, N), 100.0))
    assert (labels == PLANAR).all()


def test_quantised_plane_with_unknown_pixels():
    gt = np.full((N, N), 100.0)
    gt[10:14, 20:30] = 0.0  # unknown
    labels = label_regions(gt)
    assert (labels[10:14, 20:30] == 0).all()
    assert not (labels == THIN).any()  # an unknown patch makes no thin structure
    assert (labels[:, 36:] == PLANAR).all() and (labels[20:] == PLANAR).all()  # only its border is edge band


@pytest.mark.parametrize("quantised", [False, True])
def test_ramp_is_slanted(quantised):
    x, y = _grid()
    gt = 50.0 + 0.3 * x + 0.2 * y
    labels = label_regions(np.round(gt) if quantised else gt)  # the 8-bit staircase is still a plane
    assert (labels == SLANTED).mean() > 0.97, np.bincount(labels.ravel(), minlength=6)


def test_sphere_cap_is_curved():
    x, y = _grid()
    r2 = (x - 32) ** 2 + (y - 32) ** 2
    gt = 100.0 + np.sqrt(np.clip(25.0 ** 2 - r2, 0, None))  # curvature 1/25 = 0.04 at the top
    labels = label_regions(gt)
    inner = r2 < 12 ** 2
    assert (labels[inner] == CURVED).all()


def test_step_makes_an_edge_band():
    gt = np.full((N, N), 50.0)
    gt[:, 32:] = 100.0
    labels = label_regions(gt)
    assert (labels[:, 30:34] == EDGE).all()  # within 2 px of the step
    assert (labels[:, :26] == PLANAR).all() and (labels[:, 38:] == PLANAR).all()
    assert not (labels == THIN).any()


def test_two_pixel_bar_is_thin_a_wide_one_is_not():
    gt = np.full((N, N), 50.0)
    gt[8:56, 20:22] = 120.0  # 2 px wide
    gt[8:56, 40:50] = 120.0  # 10 px wide
    labels = label_regions(gt)
    assert (labels[12:52, 20:22] == THIN).all()
    assert not (labels[:, 36:54] == THIN).any()
    assert (labels[12:52, 44:46] == PLANAR).all()  # the wide bar's middle is a plane


def test_region_errors_add_up_and_the_gap_shares_sum_to_one():
    rng = np.random.default_rng(0)
    gt = np.full((N, N), 50.0)
    gt[:, 32:] = 100.0
    labels = label_regions(gt)
    rows = []
    for scene in ("Art", "Baby1"):
        for method, s in (("rgf", 1.0), ("full", 2.0)):
            pred = gt + s * rng.standard_normal(gt.shape)
            rows.append({"track": "paper", "scene": scene, "method": method,
                         "regions": region_errors(pred, gt, labels)})
    e = rows[0]["regions"]
    assert sum(e[r]["n"] for r in REGIONS) == e["all"]["n"] == N * N
    assert sum(e[r]["sse"] for r in REGIONS) == pytest.approx(e["all"]["sse"])
    summary = summarise_regions(rows, reference="rgf")
    full = [r for r in summary if r["method"] == "full" and r["subset"] == "all"]
    assert sum(r["dmse_share"] for r in full if r["region"] != "all") == pytest.approx(1.0)
    assert sum(r["share"] for r in full if r["region"] != "all") == pytest.approx(1.0)
    assert {r["subset"] for r in summary} == {"all", "held-out", "2006"}
