"""Issue 28, twenty-fifth stop: variants of parts of the stream, each a patch of this process (nothing here is
shipped), run by the twenty-fourth stop's ``tried_variants.py`` (same scenes, same metrics: stream ÷ frame by frame).

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-fifth-stop/tried_stream_parts.py --set fit \
        --size 120x160 --variants shipped dirichlet0 dirichlet2

Variants (besides those of ``tried_variants.py``):

* ``dirichletR`` — mask-sparse later layers, emulated on the whole frame: in each later layer the x-update solves for
  the fresh pixels dilated by R px only (CG on the masked unknowns, the other pixels fixed at their values:
  ``A_FF x_F = b_F − A_FN x_N``, the preconditioner masked, the shipped iteration count), and after each later layer
  every other pixel's state (x, the split variables, Q, the confidence) is put back: what layers that computed the
  fresh pixels alone, with no crop padding, would give;
* ``refiner-fresh`` — the refiner's output is taken at the fresh pixels only; every other pixel keeps the value
  before the refiner (the edge steps' output). Then the band as shipped;
* ``refiner-kept`` — the same at the fresh pixels; every other pixel takes the value before the refiner plus the
  refiner's correction as it was last computed there (in the first frame, or the last frame it was fresh);
* ``framelikeR`` — within R px of a changed pixel the model reads this frame's measurement (no run's mean, nothing
  held out or dropped as an outlier in time), no temporal prior, the singular gate reads the pixel, and the later
  layers run there (the holes' fill verdicts stay the stream's);
* ``fresh-matches`` — no previous match kept anywhere (every pixel searched again, as frame by frame);
* ``fresh-policy`` — the observation's offset, scale and noise level estimated again in every frame (as frame by
  frame), not kept from the previous frame while half of it was static (``keep_scale``).
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
from torch_depth_sr.post_steps import DenoiseRefineStep  # noqa: E402
from torch_depth_sr.solvers.implicit import cg_solve  # noqa: E402
from torch_depth_sr.window_max import dilate  # noqa: E402

PATCHED = [(frame, "join_runs"), (frame, "StreamMatcher"), (frame, "run_later_layers"),
           (frame.StreamFrame, "scale_policy"), (frame.StreamFrame, "post"), (stages.LinearSolver, "forward"),
           (DenoiseRefineStep, "forward")]
SHIPPED = {(owner, name): getattr(owner, name) for owner, name in PATCHED}
_SHIPPED_USE = tv.use
NOW: dict = {}  # what a patched step reads while it runs: the later layers' mask, the fresh pixels, the last correction
_MAPS = ("x", "z", "w", "e", "alpha", "q", "confidence")


def _shipped(owner, name: str):
    return SHIPPED[(owner, name)]


# ---- dirichletR -------------------------------------------------------------------------------------------------
def masked_solve(self, obs, q, mu, rhs, x0, diag=None):
    """``LinearSolver.forward`` with the unknowns restricted to ``NOW["mask"]`` (the rest fixed at ``x0``)."""
    if "mask" not in NOW:
        return _shipped(stages.LinearSolver, "forward")(self, obs, q, mu, rhs, x0, diag)
    c, K, m = self.settings, obs.K, NOW["mask"].to(x0)
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
    NOW["mask"] = mask
    try:
        s = state
        for layer in layers:
            out = layer(s, obs)
            s = replace(out, **{k: torch.where(mask, getattr(out, k), getattr(state, k)) for k in _MAPS})
    finally:
        NOW.pop("mask", None)
    return s


# ---- refiner-fresh, refiner-kept ---------------------------------------------------------------------------------
def post_noting_fresh(self, steps, x, state, obs, initial):
    NOW["fresh"] = self.fresh if self.warm else None
    try:
        return _shipped(frame.StreamFrame, "post")(self, steps, x, state, obs, initial)
    finally:
        NOW.pop("fresh", None)


def refine_at_fresh(self, x, state, obs, initial):
    out = _shipped(DenoiseRefineStep, "forward")(self, x, state, obs, initial)
    fresh = NOW.get("fresh")
    return out if fresh is None else torch.where(fresh, out, x)


def refine_kept(self, x, state, obs, initial):
    out = _shipped(DenoiseRefineStep, "forward")(self, x, state, obs, initial)
    if "fresh" not in NOW:  # a frame-by-frame restoration
        return out
    fresh, correction = NOW["fresh"], out - x
    if fresh is not None and "correction" in NOW:
        correction = torch.where(fresh, correction, NOW["correction"].to(correction))
    NOW["correction"] = correction
    return x + correction


# ---- framelikeR ---------------------------------------------------------------------------------------------------
def framelike_join(radius, y, observed, static, *args):
    """``join_runs`` as shipped, then frame-by-frame's inputs within ``radius`` px of a changed pixel."""
    runs = _shipped(frame, "join_runs")(y, observed, static, *args)
    near = dilate(~static, radius)
    no = torch.zeros_like(near)
    return runs._replace(y=torch.where(near, y, runs.y), observed=torch.where(near, observed, runs.observed),
                         outlier=torch.where(near, no, runs.outlier), held_out=torch.where(near, no, runs.held_out),
                         averaged=torch.where(near, no, runs.averaged),
                         weight=torch.where(near, torch.zeros_like(runs.weight), runs.weight),
                         fresh=runs.fresh | near)


# ---- the variants ------------------------------------------------------------------------------------------------
NAMED = {  # variant → the attributes it replaces
    "refiner-fresh": {(frame.StreamFrame, "post"): post_noting_fresh, (DenoiseRefineStep, "forward"): refine_at_fresh},
    "refiner-kept": {(frame.StreamFrame, "post"): post_noting_fresh, (DenoiseRefineStep, "forward"): refine_kept},
    "fresh-matches": {(frame, "StreamMatcher"): lambda inner, *a: inner},
    "fresh-policy": {(frame.StreamFrame, "scale_policy"): lambda self, *a: None},
}
WITH_RADIUS = {  # variant prefix, then R in px → the attributes it replaces
    "dirichlet": lambda r: {(frame, "run_later_layers"): lambda *a: dirichlet_later(r, *a),
                            (stages.LinearSolver, "forward"): masked_solve},
    "framelike": lambda r: {(frame, "join_runs"): lambda y, obs, static, *a: framelike_join(r, y, obs, static, *a)},
}


def use(variant: str) -> None:
    _SHIPPED_USE("shipped")  # the twenty-fourth stop's patches undone first (it sets frame.join_runs too)
    NOW.clear()
    for (owner, name), value in SHIPPED.items():
        setattr(owner, name, value)
    prefix = next((p for p in WITH_RADIUS if variant.startswith(p) and variant[len(p):].isdigit()), None)
    patches = NAMED.get(variant) or (WITH_RADIUS[prefix](int(variant[len(prefix):])) if prefix else None)
    if patches is None:
        _SHIPPED_USE(variant)  # shipped, or one of the twenty-fourth stop's variants (it refuses unknown names)
        return
    for (owner, name), value in patches.items():
        setattr(owner, name, value)


tv.use = use

if __name__ == "__main__":
    tv.main()
