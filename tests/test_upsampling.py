"""x⁰ of guided upsampling: first-order JBU, the depth-edge band and its consistency check."""
import torch
import torch.nn.functional as F

from torch_depth_sr.config import UpsamplingConfig
from torch_depth_sr.guided_filters import joint_bilateral_upsample, limited_slopes
from torch_depth_sr.upsampling import plane_residual, upsample_initial


def _plane(h, w, dtype=torch.float64):
    yy, xx = torch.meshgrid(torch.arange(h, dtype=dtype), torch.arange(w, dtype=dtype), indexing="ij")
    return (3 * xx - 2 * yy + 80)[None, None]


def test_first_order_jbu_is_exact_on_a_plane_whatever_the_colour():
    g = torch.Generator().manual_seed(0)
    lr = _plane(20, 24)
    rgb = 0.3 * torch.rand(1, 3, 80, 96, generator=g, dtype=torch.float64)  # texture: uneven colour weights
    first = joint_bilateral_upsample(lr, rgb, 4, first_order=True)
    zeroth = joint_bilateral_upsample(lr, rgb, 4)
    u = (torch.arange(80, dtype=torch.float64) + 0.5) / 4 - 0.5
    v = (torch.arange(96, dtype=torch.float64) + 0.5) / 4 - 0.5
    exact = 3 * v[None, :] - 2 * u[:, None] + 80
    inner = (slice(12, -12), slice(12, -12))  # the border samples have slope 0 (one-sided)
    assert float((first[0, 0] - exact)[inner].abs().max()) < 1e-9
    assert float((zeroth[0, 0] - exact)[inner].abs().max()) > 0.3  # the texture the first order removes


def test_limited_slopes_are_zero_beside_a_step_and_at_holes():
    d = torch.tensor([[1.0, 2.0, 3.0, 10.0, 11.0, 12.0]]).view(1, 1, 1, 6)
    _, sx = limited_slopes(d)
    assert sx[0, 0, 0].tolist() == [0.0, 1.0, 1.0, 1.0, 1.0, 0.0]
    mask = torch.ones_like(d)
    mask[..., 2] = 0
    _, sx = limited_slopes(d, mask)
    assert sx[0, 0, 0, 1:4].tolist() == [0.0, 0.0, 0.0]


def test_plane_residual_sees_steps_not_planes():
    step = _plane(12, 12).clone()
    assert float(plane_residual(step).abs().max()) < 1e-9
    step[..., 6:] += 20
    r = plane_residual(step)
    assert float(r[..., 5:7].min()) > 5 and float(r[..., :4].max()) < 1e-9


def _edge_scene(depth_edge: int, colour_edge: int, size=(64, 64), s=4):
    """A depth step (40 → 90) at column ``depth_edge`` and a colour step at ``colour_edge`` (fine grid)."""
    h, w = size
    gt = torch.full((1, 1, h, w), 40.0, dtype=torch.float64)
    gt[..., depth_edge:] = 90.0
    rgb = torch.full((1, 3, h, w), 0.2, dtype=torch.float64)
    rgb[..., colour_edge:] = 0.8
    lr = F.avg_pool2d(gt, s)
    return gt, lr, rgb


def _x0(lr, rgb, **overrides):
    """x⁰ ×4 of a nearly clean input (σ = 0.05) under the default upsampling settings with ``overrides``."""
    noise = torch.tensor([0.05], dtype=torch.float64)
    return upsample_initial(lr, torch.ones_like(lr), rgb, 4, UpsamplingConfig().replace(**overrides), noise=noise)


def test_the_edge_band_sharpens_a_depth_edge_the_colour_confirms():
    gt, lr, rgb = _edge_scene(30, 30)
    x0 = _x0(lr, rgb)
    no_edge_band = _x0(lr, rgb, init_edge_band=0.0)
    err = lambda v: float((v - gt).abs().mean())  # noqa: E731
    assert err(x0) < 0.7 * err(no_edge_band)


def test_a_colour_edge_the_data_do_not_confirm_does_not_move_the_depth_edge():
    # the colour edge is 8 fine pixels (2 input pixels) right of the depth edge: the JBU would drag the
    # step there; degraded again, that no longer matches the input, so the edge band is refused
    gt, lr, rgb = _edge_scene(28, 36)
    checked = _x0(lr, rgb)
    unchecked = _x0(lr, rgb, init_consistency=0.0)
    bicubic = F.interpolate(lr, scale_factor=4, mode="bicubic", align_corners=False)
    err = lambda v: float((v - gt).square().mean().sqrt())  # noqa: E731
    assert err(unchecked) > err(bicubic)  # the unchecked filter does harm here ...
    assert err(checked) <= err(bicubic) + 0.05  # ... the checked one does not
