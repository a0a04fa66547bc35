"""The masked domain-transform filter of x⁰ (guided_filters.domain_transform_filter) and the shared pull-push."""
import math
import subprocess
import sys

import numpy as np
import pytest
import torch

import torch_depth_sr.guided_filters as gfm
from torch_depth_sr import DepthRestorer, RestorerConfig
from torch_depth_sr.errors import DepthSRError, ParameterError, ShapeError
from torch_depth_sr.fill import fill_holes, pull_push
from torch_depth_sr.guided_filters import domain_transform_filter


def _reference_pass(depth, weight, rgb, sigma_space, sigma_color, iterations):
    """Gastal & Oliveira's normalised-convolution filter on (w·d, w), written as plain loops (numpy)."""
    d, wt, img = depth.double().numpy(), weight.double().numpy(), rgb.double().numpy()
    b, _, h, w = d.shape
    vals = np.concatenate([np.where(wt > 0, d * wt, 0.0), wt], axis=1)  # (B, 2, H, W)
    ratio = sigma_space / sigma_color
    coords = {}
    for axis in (3, 2):  # rows (along W), then columns (along H)
        step = 1.0 + ratio * np.abs(np.diff(img, axis=axis)).sum(axis=1, keepdims=True)
        c = np.cumsum(step, axis=axis)
        coords[axis] = np.concatenate([np.zeros_like(np.take(c, [0], axis=axis)), c], axis=axis)
    for i in range(iterations):
        sigma_i = sigma_space * math.sqrt(3) * 2 ** (iterations - i - 1) / math.sqrt(4 ** iterations - 1)
        radius = math.sqrt(3) * sigma_i
        for axis in (3, 2):
            out = np.zeros_like(vals)
            n = vals.shape[axis]
            for bi in range(b):
                for line in range(vals.shape[5 - axis]):
                    c = coords[axis][bi, 0, :, line] if axis == 2 else coords[axis][bi, 0, line, :]
                    for p in range(n):
                        box = [q for q in range(n) if abs(c[q] - c[p]) <= radius]
                        for ch in range(2):
                            seq = vals[bi, ch, :, line] if axis == 2 else vals[bi, ch, line, :]
                            mean = sum(seq[q] for q in box) / len(box)
                            if axis == 2:
                                out[bi, ch, p, line] = mean
                            else:
                                out[bi, ch, line, p] = mean
            vals = out
    num, den = vals[:, :1], vals[:, 1:]
    return torch.from_numpy(np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)), torch.from_numpy(den > 0)


def _scene(b=2, h=9, w=11, seed=0, hole_share=0.3, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    depth = (torch.rand(b, 1, h, w, generator=g) * 50 + 10).to(dtype)
    mask = (torch.rand(b, 1, h, w, generator=g) >= hole_share).to(dtype)
    rgb = torch.rand(b, 3, h, w, generator=g).to(dtype)
    return depth * mask, rgb, mask


class TestDomainTransformFilter:
    @pytest.mark.parametrize("iterations,sigma_space,sigma_color", [(1, 2.0, 0.3), (2, 3.0, 0.5), (3, 6.0, 0.2)])
    def test_matches_a_loop_reference(self, iterations, sigma_space, sigma_color):
        depth, rgb, mask = _scene()
        ss = torch.tensor(sigma_space, dtype=torch.float64).view(1, 1, 1, 1)
        sc = torch.tensor(sigma_color, dtype=torch.float64).view(1, 1, 1, 1)
        boxes = gfm._domain_boxes(rgb, ss, sc, sigma_space, iterations)
        est, filled = gfm._normalised_domain_pass(depth, mask, boxes)
        ref, ref_filled = _reference_pass(depth, mask, rgb, sigma_space, sigma_color, iterations)
        assert torch.equal(filled, ref_filled)
        torch.testing.assert_close(est, ref, rtol=1e-10, atol=1e-10)

    def test_binary_search_boxes_equal_counted_boxes(self, monkeypatch):
        depth, rgb, mask = _scene(b=3, h=40, w=33, seed=1)
        counted = domain_transform_filter(depth, rgb, mask, sigma_space=8.0, sigma_color=0.3)
        monkeypatch.setattr(gfm, "_COUNT_MAX", 0)
        searched = domain_transform_filter(depth, rgb, mask, sigma_space=8.0, sigma_color=0.3)
        assert torch.equal(counted, searched)

    @pytest.mark.parametrize("scale,offset", [(3.0, 0.0), (0.001, 5.0), (-2.0, 300.0), (1e4, -7.0)])
    def test_equivariant_to_depth_scale_and_offset(self, scale, offset):
        depth, rgb, mask = _scene(h=20, w=24, seed=2)
        out = domain_transform_filter(depth, rgb, mask)
        moved = domain_transform_filter(depth * scale + offset, rgb, mask)
        torch.testing.assert_close(moved, out * scale + offset, rtol=1e-10, atol=1e-9 * abs(scale) + 1e-9)

    def test_never_leaves_the_range_of_the_measured_values(self):
        depth, rgb, mask = _scene(b=4, h=30, w=40, seed=3, hole_share=0.5)
        depth = torch.where(mask > 0, torch.randn(depth.shape, dtype=depth.dtype) * 100, depth)  # any sign
        out = domain_transform_filter(depth, rgb, mask, sigma_space=10.0, sigma_color=2.0)
        for d, m, o in zip(depth, mask, out):
            lo, hi = d[m > 0].min(), d[m > 0].max()
            assert bool((o >= lo - 1e-9).all()) and bool((o <= hi + 1e-9).all())

    def test_does_not_leak_across_a_colour_edge(self):
        """Two surfaces of different colour: every pixel, measured or hole, keeps its own surface's depth."""
        h, w = 24, 32
        depth = torch.full((1, 1, h, w), 10.0, dtype=torch.float64)
        depth[..., 16:] = 90.0
        rgb = torch.zeros(1, 3, h, w, dtype=torch.float64)
        rgb[..., 16:] = 1.0
        mask = torch.ones_like(depth)
        mask[..., 5:12, 12:20] = 0  # a hole across the edge
        out = domain_transform_filter(depth * mask, rgb, mask, sigma_space=12.0, sigma_color=0.5)
        torch.testing.assert_close(out, depth, rtol=0, atol=1e-9)  # any leak would move a pixel by its weight × 80

    def test_constant_depth_with_holes_stays_constant(self):
        depth = torch.full((2, 1, 20, 26), 42.0)
        depth[0, 0, 3:9, 4:15] = 0
        depth[1, 0, ::3, ::2] = 0
        out = domain_transform_filter(depth, torch.rand(2, 3, 20, 26))
        torch.testing.assert_close(out, torch.full_like(out, 42.0), rtol=1e-6, atol=0)

    def test_hole_enclosed_by_a_colour_edge_is_filled(self):
        """No measured pixel reaches a hole inside a closed colour edge: fill passes and pull-push fill it."""
        depth = torch.full((1, 1, 30, 30), 7.0)
        depth[..., 10:20, 10:20] = 0
        rgb = torch.zeros(1, 3, 30, 30)
        rgb[..., 10:20, 10:20] = 1.0  # the hole has its own colour
        for passes in (0, 2):
            out = domain_transform_filter(depth, rgb, fill_passes=passes, sigma_color=0.01)
            torch.testing.assert_close(out, torch.full_like(out, 7.0))

    def test_a_sample_without_measurements_comes_back_zero(self):
        depth = torch.zeros(2, 1, 12, 12)
        depth[1] = 5.0
        out = domain_transform_filter(depth, torch.rand(2, 3, 12, 12))
        assert torch.equal(out[0], torch.zeros_like(out[0]))
        torch.testing.assert_close(out[1], torch.full_like(out[1], 5.0))

    def test_batch_equals_one_sample_at_a_time_and_per_sample_sigmas(self):
        depth, rgb, mask = _scene(b=3, h=25, w=19, seed=4, dtype=torch.float32)
        ss, sc = torch.tensor([2.0, 6.0, 19.0]), torch.tensor([0.05, 0.2, 1.0])  # 19 px: binary-search boxes
        batched = domain_transform_filter(depth, rgb, mask, sigma_space=ss, sigma_color=sc)
        for i in range(3):
            one = domain_transform_filter(depth[i:i + 1], rgb[i:i + 1], mask[i:i + 1],
                                          sigma_space=float(ss[i]), sigma_color=float(sc[i]))
            torch.testing.assert_close(batched[i:i + 1], one, rtol=1e-6, atol=1e-5)

    def test_dtype_device_and_no_in_place_change(self):
        depth, rgb, mask = _scene(h=16, w=16, seed=5)
        for dtype in (torch.float32, torch.float64):
            d, r, m = depth.to(dtype), rgb.to(dtype), mask.to(dtype)
            before = (d.clone(), r.clone(), m.clone())
            out = domain_transform_filter(d, r, m)
            assert out.dtype == dtype and out.device == d.device and out.shape == d.shape
            assert all(torch.equal(a, b) for a, b in zip(before, (d, r, m)))
        a = domain_transform_filter(depth.float(), rgb.float(), mask.float())
        b = domain_transform_filter(depth, rgb, mask)
        torch.testing.assert_close(a.double(), b, rtol=1e-5, atol=1e-4)

    def test_noncontiguous_input(self):
        depth, rgb, mask = _scene(h=16, w=20, seed=6)
        out = domain_transform_filter(depth.transpose(-1, -2), rgb.transpose(-1, -2), mask.transpose(-1, -2))
        ref = domain_transform_filter(*(t.transpose(-1, -2).contiguous() for t in (depth, rgb, mask)))
        torch.testing.assert_close(out, ref)

    def test_empty_batch(self):
        out = domain_transform_filter(torch.zeros(0, 1, 8, 8), torch.zeros(0, 3, 8, 8))
        assert out.shape == (0, 1, 8, 8)

    def test_gradcheck(self):
        depth, rgb, mask = _scene(b=1, h=6, w=7, seed=7)
        depth = depth.clone().requires_grad_(True)
        assert torch.autograd.gradcheck(lambda d: domain_transform_filter(d, rgb, mask), (depth,))

    @pytest.mark.parametrize("kwargs,error,match", [
        ({"iterations": 0}, DepthSRError, "iterations"),
        ({"iterations": 1.5}, DepthSRError, "iterations"),
        ({"fill_passes": -1}, DepthSRError, "fill_passes"),
        ({"sigma_space": 0.0}, DepthSRError, "sigma_space"),
        ({"sigma_color": -1.0}, DepthSRError, "sigma_color"),
        ({"sigma_color": torch.ones(3)}, ShapeError, "sigma_color"),
    ])
    def test_exceptions(self, kwargs, error, match):
        depth, rgb, mask = _scene(h=8, w=8)
        with pytest.raises(error, match=match):
            domain_transform_filter(depth, rgb, mask, **kwargs)

    def test_shape_errors(self):
        with pytest.raises(ShapeError, match="rgb"):
            domain_transform_filter(torch.ones(1, 1, 8, 8), torch.ones(1, 3, 8, 9))
        with pytest.raises(ShapeError, match="channel"):
            domain_transform_filter(torch.ones(1, 1, 8, 8), torch.ones(1, 1, 8, 8))


class TestPullPush:
    def test_nearest_and_bilinear_keep_weighted_pixels_and_fill_the_rest(self):
        g = torch.Generator().manual_seed(0)
        v = torch.rand(2, 3, 13, 17, generator=g)
        wt = (torch.rand(2, 1, 13, 17, generator=g) > 0.7).float()
        for mode in ("nearest", "bilinear"):
            out = pull_push(v, wt, upsample=mode)
            assert torch.equal(out[wt.expand_as(v) > 0], v[wt.expand_as(v) > 0])
            assert bool(((out >= v.min()) & (out <= v.max())).all())

    @pytest.mark.parametrize("shape", [(1, 9), (9, 1), (1, 1)])
    def test_one_pixel_wide_maps_are_filled(self, shape):
        v = torch.zeros(1, 1, *shape)
        v.view(-1)[0] = 4.0
        out = pull_push(v, (v > 0).float(), upsample="nearest")
        torch.testing.assert_close(out, torch.full_like(out, 4.0))

    def test_fill_holes_is_the_bilinear_pull_push(self):
        y = torch.rand(1, 1, 11, 14) + 1
        m = (torch.rand(1, 1, 11, 14) > 0.5).float()
        assert torch.equal(fill_holes(y * m, m), pull_push(y * m, m, upsample="bilinear"))

    def test_unknown_mode(self):
        with pytest.raises(ValueError, match="upsample"):
            pull_push(torch.ones(1, 1, 4, 4), torch.ones(1, 1, 4, 4), upsample="cubic")


class TestInitialEstimate:
    @pytest.mark.parametrize("init_fill", ["domain", "jbf"])
    def test_init_fill_picks_the_filter(self, scene, init_fill):
        from torch_depth_sr.guided_filters import joint_bilateral_filter
        from torch_depth_sr.initial import initial_estimate

        c = RestorerConfig().replace(initial={"fill": init_fill}, sided_fill=None).initial
        y, rgb = scene["depth"], scene["rgb"]
        observed = (y > 0).float()
        est = initial_estimate(y, observed, rgb, 1, c, sided_fill=None)
        if init_fill == "domain":
            ref = domain_transform_filter(y, rgb, observed, sigma_space=c.dt_sigma_space,
                                          sigma_color=c.dt_sigma_color, iterations=c.dt_iterations)
        else:
            ref = joint_bilateral_filter(y, rgb, observed, kernel_size=c.kernel_size,
                                         sigma_space=c.sigma_space, sigma_color=c.sigma_color)
        assert torch.equal(est, ref)

    def test_domain_is_the_default(self):
        assert RestorerConfig().initial.fill == "domain"

    @pytest.mark.parametrize("field,value", [("fill", "guided"), ("dt_sigma_space", 0.0),
                                             ("dt_sigma_color", -0.1), ("dt_iterations", 0)])
    def test_config_refuses_bad_values(self, field, value):
        with pytest.raises(ParameterError, match=f"initial.{field}"):
            RestorerConfig().replace(initial={field: value})

    def test_the_model_does_not_import_the_baselines(self):
        code = ("import sys, torch\nfrom torch_depth_sr import DepthRestorer\n"
                "y = torch.rand(1, 1, 24, 24) * 10 + 1; y[..., 5:9, 5:9] = 0\n"
                "DepthRestorer()(y, torch.rand(1, 3, 24, 24))\n"
                "DepthRestorer()(y[..., ::2, ::2], torch.rand(1, 3, 24, 24), scale_factor=2)\n"
                "print(sorted(k for k in sys.modules if k.startswith('torch_depth_sr.baselines')))\n")
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
        assert out.stdout.strip() == "[]"
