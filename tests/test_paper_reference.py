"""The ``paper`` configuration against a hand-written loop of the paper's algorithm (model.md, Algorithm 3.1).

The loop below is written from ``shared/docs/model.md`` and the ``paper`` settings, not from the model's code: the
half-quadratic splitting of

    min_{x,e}  1/2 ||Q (y - x - e)||^2 + lam ||Dx||_1 + eta ||Dx - alpha||_1 + gamma ||e||_1      (denoising, K = I)

one plain iteration per layer, in the order of model.md: z, w, e, alpha (block matching when scheduled), Q, then x
from (Q + (mu1 + mu2) D^T D) x = Q (y - e) + mu1 D^T z + mu2 D^T (w + alpha).

Primitives it reuses from the package (each tested on its own elsewhere): the scale policy (``noise.depth_scale``,
``noise.quantisation_step``), the pull-push fill of x0 (``fill.fill_holes``), the unfold oracle of block matching
(``block_match_reference``), the singular-pixel test (``detect_singular``, its plain torch path), the discrete
gradient and its adjoint, and the DCT preconditioner of the CG solve (``NeumannPreconditioner``). Written out here:
the shrinkages, the nonlocal alpha (a gather of the matched centres' gradients), the e / z / w / Q / x updates, the
right-hand side, and preconditioned CG with the model's fixed iteration schedule (a sample whose relative residual
reaches the tolerance stops changing), and the return to depth units.

What ``paper`` is (config.py at 046c797, ABLATIONS["paper"]): all three terms, 5x5 blocks in a 21x21 window,
k = 10, re-matching from scratch on the current x in layers 2 and 5, x0 = y with its holes pulled-pushed, none of the
library's extensions (no guided prior, no neighbour/line support or gate of the singular test, no fidelity band,
no nonlocal value prior; so no edge snapping either, which runs only on samples the gate finds outliers in).
"""
from __future__ import annotations

import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.block_matching import block_match_reference
from torch_depth_sr.datasets.synthetic import make_scene
from torch_depth_sr.fill import fill_holes
from torch_depth_sr.noise import depth_scale, implausible, quantisation_step
from torch_depth_sr.operators import grad, grad_adjoint
from torch_depth_sr.singular import detect_singular
from torch_depth_sr.solvers.dct import NeumannPreconditioner

# the paper configuration's settings (model.md; config.py ABLATIONS["paper"] on top of the defaults)
PAPER = dict(num_layers=8, lam=1.0, eta=2.0, gamma=3.0, mu1=2.0, mu2=0.5, block_size=5, search_window=21, k=10,
             color_weight=400.0, temperature=0.5, match_layers=(2, 5), singular_tau=0.5, singular_sigma_floor=2.5,
             singular_rounds=3, cg_fixed_iters=(5, 4, 3, 3, 3, 2, 2, 1), cg_tol=1e-3)


def _input(dtype=torch.float32):
    """Two 24x32 scenes, sigma = 3 noise, a hole in each, impulses and a flying pixel."""
    scenes = [make_scene(24, 32, seed=s) for s in (11, 12)]
    gt = torch.stack([s["gt"] for s in scenes]).to(dtype)
    rgb = torch.stack([s["rgb"] for s in scenes]).to(dtype)
    g = torch.Generator().manual_seed(5)
    y = gt + 3.0 * torch.randn(gt.shape, generator=g, dtype=torch.float64).to(dtype)
    y[0, :, 5:8, 9:13] = 0
    y[1, :, 16:19, 3:6] = 0
    for b, r, c, d in ((0, 15, 20, 40.0), (0, 20, 27, -35.0), (1, 4, 25, 45.0), (1, 12, 12, -40.0)):
        y[b, 0, r, c] += d
    jump = (gt[0, 0, :, 2:] - gt[0, 0, :, :-2]).abs() > 20
    r, c = jump.nonzero()[0].tolist()
    y[0, 0, r, c + 1] = 0.5 * (gt[0, 0, r, c] + gt[0, 0, r, c + 2])
    return y.clamp_min(0), rgb


def soft(v, t):
    """sign(v) max(|v| - t, 0)."""
    return torch.sign(v) * torch.clamp(v.abs() - t, min=0)


def nonlocal_alpha(dx, index, weight):
    """alpha_i = sum_m w[m, i] (Dx)[index[m, i]], the weighted mean of the matched centres' gradients."""
    b, c, h, w = dx.shape
    k = index.shape[1]
    flat = dx.reshape(b, c, 1, h * w).expand(b, c, k, h * w)
    at_centres = torch.gather(flat, 3, index.reshape(b, 1, k, h * w).expand(b, c, k, h * w)).view(b, c, k, h, w)
    return (weight.unsqueeze(1).to(dx.dtype) * at_centres).sum(2)


def pcg(apply_a, rhs, x, precond, iterations: int, tol: float):
    """Preconditioned CG (Saad, Alg. 9.1) per sample, ``iterations`` steps from ``x``; a sample whose relative
    residual ||r|| / ||rhs|| is at most ``tol`` (before or after a step) stops changing."""
    def dot(u, v):
        return (u * v).flatten(1).sum(1).view(-1, 1, 1, 1)

    bnorm = rhs.flatten(1).norm(dim=1).view(-1, 1, 1, 1)
    bnorm = torch.where(bnorm > 0, bnorm, torch.ones_like(bnorm))
    r = rhs - apply_a(x)
    done = r.flatten(1).norm(dim=1).view(-1, 1, 1, 1) / bnorm <= tol
    zr = precond(r)
    p = zr
    rz = dot(r, zr)
    for _ in range(iterations):
        ap = apply_a(p)
        pap = dot(p, ap)
        step = ~done & (pap > 0)
        a = torch.where(step, rz / torch.where(step, pap, torch.ones_like(pap)), torch.zeros_like(pap))
        x = x + a * p
        r = r - a * ap
        done = done | ~step | (r.flatten(1).norm(dim=1).view(-1, 1, 1, 1) / bnorm <= tol)
        zr = precond(r)
        rz_new = dot(r, zr)
        keep = ~done & (rz != 0)
        beta = torch.where(keep, rz_new / torch.where(keep, rz, torch.ones_like(rz)), torch.zeros_like(rz))
        p = zr + beta * p
        rz = rz_new
    return x


def paper_reference(y, rgb, weights, P=PAPER):
    """The paper's algorithm on ``y (B,1,H,W)`` (0 = missing) guided by ``rgb``: ``(x, Q, P(x), e)`` in depth units.

    ``weights``: per layer (lam, eta, gamma, mu1, mu2) as the model holds them (float32 tensors); h and rho are
    stored as float32 logs by the model (it learns h in log space), so they are exp(log(v)) in float32 here too."""
    dt = y.dtype
    observed = (y > 0).to(dt)
    # scale policy: y_n = (y - median) / sigma_hat (every threshold is in noise-sigma units)
    step = quantisation_step(y, observed)
    offset, scale, _ = depth_scale(y, observed, None, step=step)
    assert not implausible(y, observed, scale).any()  # (the input has no glitches to drop)
    o, s = offset.view(-1, 1, 1, 1), scale.view(-1, 1, 1, 1)
    yn = torch.where(observed > 0, (y - o) / s, torch.zeros_like(y))
    h = torch.tensor(P["temperature"]).log().exp()
    rho = torch.tensor(P["color_weight"]).log().exp()

    def match(x, trust):  # the k blocks most similar to each pixel's and softmax(-d/h) weights, (B,k,H,W)
        per_sample = [block_match_reference(x[i:i + 1], rgb[i:i + 1], trust[i:i + 1], block_size=P["block_size"],
                                            search_window=P["search_window"], k=P["k"], color_weight=rho,
                                            temperature=h) for i in range(x.shape[0])]  # (the oracle's memory)
        return type(per_sample[0])(*(torch.cat(f) for f in zip(*per_sample)))

    # initial values: x0 = y with the holes filled by pull-push; Q0 = measured; z = w = e = 0; alpha0 from x0's matches
    x = torch.where(observed > 0, yn, fill_holes(yn, observed))
    q, conf = observed, observed
    z = w = torch.zeros_like(torch.cat([x, x], 1))
    e = torch.zeros_like(x)
    matches = match(x, q)
    alpha = nonlocal_alpha(grad(x), matches.index, matches.weight)
    for layer in range(P["num_layers"]):
        lam, eta, gamma, mu1, mu2 = (v.to(dt) for v in weights[layer])
        dx = grad(x)
        z = soft(dx, lam / mu1)                         # 1. z = soft(Dx, lam/mu1)
        w = soft(dx - alpha, eta / mu2)                 # 2. w = soft(Dx - alpha, eta/mu2)
        e = q * soft(yn - x, gamma)                     # 3. e = Q soft(y - x, gamma)
        if layer in P["match_layers"]:                  # 4. alpha: match x again when scheduled, then the mean
            matches = match(x, q)
        alpha = nonlocal_alpha(dx, matches.index, matches.weight)
        q, conf = detect_singular(yn, x, observed, matches, sigma_floor=P["singular_sigma_floor"],
                                  tau=P["singular_tau"], rounds=P["singular_rounds"], return_confidence=True,
                                  backend="torch")      # 5. Q: the singular-pixel test
        q, conf = q.to(dt), conf.to(dt)
        # 6. x: (Q + mu D^T D) x = Q(y - e) + mu1 D^T z + mu2 D^T(w + alpha), mu = mu1 + mu2, by preconditioned CG
        mu = mu1 + mu2
        rhs = q * (yn - e) + mu1 * grad_adjoint(z) + mu2 * grad_adjoint(w + alpha)

        def apply_a(v, q=q, mu=mu):
            return q * v + mu * grad_adjoint(grad(v))

        precond = NeumannPreconditioner(q.flatten(1).mean(1), mu)
        iterations = P["cg_fixed_iters"][min(layer, len(P["cg_fixed_iters"]) - 1)]
        x = pcg(apply_a, rhs, x, precond, iterations, P["cg_tol"])
    return x * s + o, q, conf * observed, e * s


def _model_weights(model):
    """Each layer's (lam, eta, gamma, mu1, mu2) as the model computes with them (float32), checked against the
    paper configuration's values."""
    out = []
    for values in model.layer_parameters():
        v = tuple(torch.tensor(values[n], dtype=torch.float32) for n in ("lam", "eta", "gamma", "mu1", "mu2"))
        torch.testing.assert_close(torch.stack(v), torch.tensor([PAPER[n] for n in ("lam", "eta", "gamma", "mu1",
                                                                                     "mu2")]), rtol=1e-6, atol=0)
        out.append(v)
    assert len(out) == PAPER["num_layers"]
    return out


def _check(dtype, rel):
    y, rgb = _input(dtype)
    model = DepthRestorer.from_preset("paper")
    r = model.restore_with_details(y, rgb)
    x, q, conf, e = paper_reference(y, rgb, _model_weights(model))
    rng = float(y.max() - y[y > 0].min())
    torch.testing.assert_close(r.depth, x, rtol=0, atol=rel * rng)
    torch.testing.assert_close(r.outliers, e, rtol=0, atol=rel * rng)
    torch.testing.assert_close(r.confidence, conf, rtol=0, atol=rel * 10)
    assert torch.equal(r.trusted.to(q.dtype), q)
    assert 0 < float((1 - q)[y > 0].sum()) < 0.2 * y.numel()  # the test found some singular pixels, not most
    assert float(e.abs().sum()) > 0 and len(r.info["cg_iterations"]) == PAPER["num_layers"]


def test_paper_forward_is_the_paper_algorithm():
    # float32: the reference computes in float32 too; the difference is float round-off (different operation
    # order in block matching, CG and the singular test), relative to the depth range
    _check(torch.float32, 1e-5)


def test_paper_forward_is_the_paper_algorithm_float64():
    _check(torch.float64, 1e-10)
