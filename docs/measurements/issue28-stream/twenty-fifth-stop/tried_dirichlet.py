"""Issue 28, twenty-fifth stop: would mask-sparse later layers keep the stream's accuracy? An emulation, as a patch
of this process (nothing here is shipped, and it is slower than the crops: only the figures are read), run by the
twenty-fourth stop's ``tried_variants.py`` (same scenes, same metrics: stream ÷ frame by frame).

The shipped stream runs the later layers on crops around the fresh pixels, padded by what the layers read (28 px at
the fast tier), and keeps their values at the fresh pixels only. Layers that computed the fresh pixels alone would
skip the padding: every other pixel keeps the first layer's state and is a fixed boundary of the later layers. This
emulates that on the whole frame: in each later layer the x-update solves for the fresh pixels only (CG on the
masked unknowns, the other pixels fixed at their values: ``A_FF x_F = b_F − A_FN x_N``, the preconditioner masked),
and after each later layer every other pixel's state (x, the split variables, Q, the confidence) is put back.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-fifth-stop/tried_dirichlet.py --set tuning \
        --size 480x640 --variants shipped dirichlet0 dirichlet2

Variants (besides those of ``tried_variants.py``): ``dirichletR`` — the later layers on the fresh pixels dilated by
R px, the rest fixed (the same CG iteration count per layer as shipped).
"""
from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "twenty-fourth-stop"))
import tried_variants as tv  # noqa: E402  (the twenty-fourth stop's script: scenes, metrics, report)

import torch_depth_sr.stages as stages  # noqa: E402
import torch_depth_sr.stream.frame as frame  # noqa: E402
from torch_depth_sr.operators import laplacian  # noqa: E402
from torch_depth_sr.solvers.implicit import cg_solve  # noqa: E402
from torch_depth_sr.stream.matching import dilate  # noqa: E402

SHIPPED = (frame.run_later_layers, stages.LinearSolver.forward)
_SHIPPED_USE = tv.use
MASK: dict = {}  # the unknowns of the later layers' x-updates while they run
_MAPS = ("x", "z", "w", "e", "alpha", "q", "confidence")


def masked_solve(self, obs, q, mu, rhs, x0, diag=None):
    """``LinearSolver.forward`` with the unknowns restricted to ``MASK["m"]`` (the rest fixed at ``x0``)."""
    if "m" not in MASK:
        return SHIPPED[1](self, obs, q, mu, rhs, x0, diag)
    c, K, m = self.settings, obs.K, MASK["m"].to(x0)
    q = q.detach()

    def apply_a(v):
        av = K.adjoint(q * K(v)) + mu * laplacian(v)
        return av if diag is None else av + diag * v

    fixed = (1 - m) * x0.detach()
    pre = self._preconditioner(q, diag, mu, K.scale)
    res = cg_solve(lambda v: m * apply_a(m * v), m * (rhs - apply_a(fixed)), x0=m * x0.detach(),
                   precond=None if pre is None else (lambda r: m * pre(m * r)), tol=c.tol, max_iter=self.max_iter,
                   implicit=c.implicit_backward, params=(), early_exit=self.early_exit, backward_max_iter=c.max_iter)
    obs.log.cg_iterations.append(res.iterations)
    return m * res.x + fixed


def dirichlet_later(radius, layers, state, obs, fresh):
    """The later layers with every pixel farther than ``radius`` px from a fresh one fixed at ``state``."""
    if len(layers) == 0 or not bool(fresh.any()):
        return state
    mask = dilate(fresh, radius) if radius > 0 else fresh
    MASK["m"] = mask
    try:
        s = state
        for layer in layers:
            out = layer(s, obs)
            s = replace(out, **{k: torch.where(mask, getattr(out, k), getattr(state, k)) for k in _MAPS})
    finally:
        MASK.clear()
    return s


def use(variant: str) -> None:
    _SHIPPED_USE("shipped")
    frame.run_later_layers, stages.LinearSolver.forward = SHIPPED
    MASK.clear()
    if variant.startswith("dirichlet"):
        radius = int(variant[9:])
        frame.run_later_layers = lambda *a: dirichlet_later(radius, *a)
        stages.LinearSolver.forward = masked_solve
    else:
        _SHIPPED_USE(variant)


tv.use = use

if __name__ == "__main__":
    tv.main()
