"""The x-update over an update region (``Observation.update_region``, a stream's later layers): the region's unknowns
solved with every other pixel fixed, preconditioned by the operator's diagonal; a sample whose region is the whole
frame solved as without one."""
from types import SimpleNamespace

import torch

from torch_depth_sr.config import SolverConfig
from torch_depth_sr.operators import Identity, laplacian
from torch_depth_sr.stages import LinearSolver
from torch_depth_sr.state import RunLog


def _system(seed=0, b=2, h=20, w=24):
    g = torch.Generator().manual_seed(seed)
    q = (torch.rand(b, 1, h, w, generator=g) > 0.2).double()
    diag = torch.rand(b, 1, h, w, generator=g, dtype=torch.float64)
    rhs = torch.randn(b, 1, h, w, generator=g, dtype=torch.float64)
    x0 = torch.randn(b, 1, h, w, generator=g, dtype=torch.float64)
    return q, torch.tensor(2.5, dtype=torch.float64), rhs, x0, diag


def _solve(region, fixed_iters, *system):
    solver = LinearSolver(SolverConfig(fixed_iters=fixed_iters, tol=1e-12, max_iter=500), 0)
    obs = SimpleNamespace(K=Identity(), update_region=region, log=RunLog())
    return solver(obs, *system[:3], system[3], diag=system[4])


def test_a_region_solve_fixes_the_other_pixels_and_solves_the_region_exactly():
    q, mu, rhs, x0, diag = system = _system()
    region = torch.zeros_like(x0, dtype=torch.bool)
    region[0, :, 4:12, 5:15] = True
    region[1, :, 10:18, 0:9] = True
    x = _solve(region, (), *system)  # CG to the tolerance
    assert torch.equal(x[~region], x0[~region])
    residual = q * x + mu * laplacian(x) + diag * x - rhs  # A x − b
    assert residual[region].abs().max() < 1e-8  # the region's rows hold, the other pixels fixed
    assert residual[~region].abs().max() > 1e-3  # (the others' rows do not: they were not solved for)


def test_a_region_that_is_the_whole_frame_is_solved_as_without_one():
    system = _system()
    region = torch.ones_like(system[3], dtype=torch.bool)
    region[1, :, 3:5, 3:5] = False  # the second sample's region leaves pixels out; the first's is the whole frame
    with_region = _solve(region, (1,), *system)
    without = _solve(None, (1,), *system)
    torch.testing.assert_close(with_region[0], without[0], rtol=1e-12, atol=1e-12)
    assert not torch.allclose(with_region[1], without[1])
