"""Every ShapeError says which shape arrived (``actual``) and what is allowed (``expected``)."""
import ast
from pathlib import Path

import numpy as np
import pytest
import torch

import torch_depth_sr
from torch_depth_sr.block_matching import block_match, gather_neighbors
from torch_depth_sr.errors import ShapeError
from torch_depth_sr.metrics import bad_pixel_rate, rmse
from torch_depth_sr.operators import area_downsample, grad_adjoint
from torch_depth_sr.shrinkage import group_soft_threshold, soft_threshold
from torch_depth_sr.solvers import conjugate_gradient, solve_neumann

PACKAGE = Path(torch_depth_sr.__file__).parent


def _is_shape_error(node: ast.AST) -> bool:
    return (isinstance(node, ast.Name) and node.id == "ShapeError") or \
        (isinstance(node, ast.Attribute) and node.attr == "ShapeError")


def _shape_error_sites():
    """(file:line, problem) of every ShapeError the package builds or raises."""
    sites, offenders = 0, []
    for path in sorted(PACKAGE.rglob("*.py")):
        where = path.relative_to(PACKAGE.parent)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Raise) and node.exc is not None and _is_shape_error(node.exc):
                offenders.append(f"{where}:{node.lineno}: raises the ShapeError class without arguments")
            if not (isinstance(node, ast.Call) and _is_shape_error(node.func)):
                continue
            sites += 1
            given = {k.arg: k.value for k in node.keywords}
            for name in ("actual", "expected"):
                value = given.get(name)
                if value is None:
                    offenders.append(f"{where}:{node.lineno}: ShapeError(...) without {name}=")
                elif isinstance(value, ast.Constant) and value.value is None:
                    offenders.append(f"{where}:{node.lineno}: ShapeError(...) with {name}=None")
    return sites, offenders


def test_every_shape_error_states_actual_and_expected():
    sites, offenders = _shape_error_sites()
    assert sites >= 20, f"found only {sites} ShapeError calls under {PACKAGE}; is the walk looking in the right place?"
    assert not offenders, "ShapeError without actual=/expected=:\n" + "\n".join(offenders)


def _raises(fn, *args, **kwargs) -> ShapeError:
    with pytest.raises(ShapeError) as info:
        fn(*args, **kwargs)
    err = info.value
    assert isinstance(err.expected, str) and err.expected.strip(), err
    return err


@pytest.mark.parametrize("call, actual", [
    (lambda: area_downsample(torch.rand(1, 1, 7, 9), 3), (1, 1, 7, 9)),
    (lambda: grad_adjoint(torch.rand(1, 3, 4, 4)), (1, 3, 4, 4)),
    (lambda: soft_threshold(torch.zeros(3, 1, 4, 4), torch.ones(5)), (5,)),
    (lambda: group_soft_threshold(torch.zeros(2, 2, 3), 1.0, dim=4), (2, 2, 3)),
    (lambda: block_match(torch.rand(1, 1, 4, 9), search_window=3, k=1), (1, 1, 4, 9)),
    (lambda: block_match(torch.rand(1, 1, 9, 9), search_window=3, k=1, temperature=torch.ones(2, 1)), (2, 1)),
    (lambda: gather_neighbors(torch.rand(1, 1, 4, 4), torch.zeros(1, 2, 5, 4, dtype=torch.int64)), (1, 2, 5, 4)),
    (lambda: rmse(torch.ones(1, 1, 4, 4), torch.ones(1, 1, 4, 5)), (1, 1, 4, 4)),
    (lambda: rmse(torch.ones(4, 4), torch.ones(4, 4), np.ones((3, 3))), (3, 3)),
    (lambda: bad_pixel_rate(torch.ones(2, 1, 4, 4), torch.ones(2, 1, 4, 4), threshold=[1.0, 2.0, 3.0]), (3,)),
    (lambda: conjugate_gradient(lambda v: v, torch.zeros(2, 1, 4, 4), x0=torch.zeros(2, 1, 4, 5)), (2, 1, 4, 5)),
    (lambda: conjugate_gradient(lambda v: v[..., :2], torch.ones(2, 1, 4, 4)), (2, 1, 4, 2)),
    (lambda: solve_neumann(torch.zeros(2, 1, 4, 4), torch.ones(3), 1.0), (3,)),
])
def test_shape_error_reports_the_shape_that_arrived(call, actual):
    err = _raises(call)
    assert err.actual == actual


def test_two_tensors_report_the_offending_one_and_name_the_other():
    err = _raises(gather_neighbors, torch.rand(1, 1, 4, 4), torch.zeros(1, 2, 5, 4, dtype=torch.int64))
    assert err.actual == (1, 2, 5, 4) and "(1, 1, 4, 4)" in str(err) and "(4, 4)" in err.expected
