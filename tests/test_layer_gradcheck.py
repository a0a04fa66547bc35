"""gradcheck (float64) of one unrolled layer with respect to its parameters, unrolled and implicit CG."""
import pytest
import torch
from torch.func import functional_call

from torch_depth_sr import DepthRestorer


@pytest.mark.parametrize("implicit", [False, True])
def test_layer_gradcheck(implicit):
    g = torch.Generator().manual_seed(0)
    y = (torch.rand(1, 1, 10, 12, generator=g, dtype=torch.float64) * 20 + 50)
    y[..., 3, 4] = 0  # a hole
    rgb = torch.rand(1, 3, 10, 12, generator=g, dtype=torch.float64)
    # CG to convergence: a truncated CG's result depends on the preconditioner, which is built from the detached
    # μ, so the gradient of a fixed-iteration solve (the default) is not the exact derivative of its output
    model = DepthRestorer(trainable=True, num_layers=1, block_matching={"search_window": 5, "k": 3},
                          solver=dict(tol=1e-13, max_iter=500, fixed_iters=(), implicit_backward=implicit))
    names = [f"layers.0.raw_{n}" for n in ("lam", "eta", "gamma", "mu1", "mu2")] + ["block_matcher.log_temperature"]
    start = tuple(dict(model.named_parameters())[n].detach().double().clone().requires_grad_() for n in names)

    def f(*params):
        return functional_call(model, dict(zip(names, params)), (y, rgb))

    assert torch.autograd.gradcheck(f, start, eps=1e-6, atol=1e-5, rtol=1e-4)
