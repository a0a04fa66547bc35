"""The operators and the shrinkage under ``torch.compile`` equal eager mode (issue 10 item 5), on ``--device`` in
every ``--dtype``: the layer's arithmetic can be captured as a graph (issue 13: a capturable forward).

``backend="aot_eager"`` traces through dynamo and AOTAutograd without generating code, so the test needs no C++
compiler (CI has none); a graph break or a changed result fails it.
"""
import pytest
import torch

from torch_depth_sr.operators import AreaDownsample, BicubicDownsample, grad, grad_adjoint, laplacian
from torch_depth_sr.shrinkage import group_soft_threshold, soft_threshold

CASES = {
    "grad": lambda x: grad(x),
    "grad_adjoint": lambda x: grad_adjoint(torch.cat([x, 0.5 * x], dim=1)),
    "laplacian": lambda x: laplacian(x),
    "area_downsample": lambda x: AreaDownsample(2)(x),
    "area_downsample_adjoint": lambda x: AreaDownsample(2).adjoint(x[..., :8, :10]),
    "bicubic_downsample": lambda x: BicubicDownsample(2)(x),
    "soft_threshold": lambda x: soft_threshold(x, 0.3),
    "group_soft_threshold": lambda x: group_soft_threshold(torch.cat([x, -x], dim=1), 0.3),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_compiled_equals_eager(name, device, float_dtype, tolerance):
    torch._dynamo.reset()
    fn = CASES[name]
    x = torch.randn(2, 1, 16, 20, generator=torch.Generator().manual_seed(0)).to(device=device, dtype=float_dtype)
    compiled = torch.compile(fn, backend="aot_eager", fullgraph=True)
    torch.testing.assert_close(compiled(x), fn(x), **tolerance)


def test_compiled_gradient_equals_eager(device, float_dtype, tolerance):
    """Backward through the compiled TV shrinkage step (the unrolled layer's z-update) equals eager."""
    torch._dynamo.reset()

    def step(x):
        return grad_adjoint(soft_threshold(grad(x), 0.2)).square().sum()

    x = torch.randn(1, 1, 12, 14, generator=torch.Generator().manual_seed(1)).to(device=device, dtype=float_dtype)
    xe = x.clone().requires_grad_(True)
    xc = x.clone().requires_grad_(True)
    step(xe).backward()
    torch.compile(step, backend="aot_eager", fullgraph=True)(xc).backward()
    torch.testing.assert_close(xc.grad, xe.grad, **tolerance)
