"""Patch-based sparse coding over a per-image learned dictionary (K-SVD style denoising).

Elad & Aharon, "Image Denoising Via Sparse and Redundant Representations Over Learned
Dictionaries", IEEE TIP 2006; Aharon, Elad & Bruckstein, "K-SVD", IEEE TSP 2006; approximate
K-SVD from Rubinstein, Zibulevsky & Elad, Technion CS-2008-08; MOD from Engan, Aase & Husoy,
ICASSP 1999; OMP from Pati, Rezaiifar & Krishnaprasad 1993. Missing pixels are handled by
masking them out of the fit (Mairal, Elad & Sapiro, "Sparse Representation for Color Image
Restoration", IEEE TIP 2008).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import nn

from .._checks import check_min_size, check_same_hw, check_same_shape
from ..errors import DepthSRError, ShapeError
from ..noise import estimate_noise_sigma as _estimate_noise_sigma
from .jbf import _check_depth, _check_rgb, _pull_push_fill, _resolve_mask

__all__ = [
    "DictionaryDenoise",
    "OMPResult",
    "batched_omp",
    "dictionary_denoise",
    "estimate_noise_sigma",
    "overcomplete_dct_dictionary",
]


class OMPResult(NamedTuple):
    """Result of :func:`batched_omp`.

    Attributes:
        coef: (N, K) sparse codes; ``X[n] ≈ D @ coef[n]`` on the observed entries.
        n_active: (N,) int64 number of atoms selected per signal (no gradient).
        residual: (N,) squared residual norm over the observed entries.
    """

    coef: torch.Tensor
    n_active: torch.Tensor
    residual: torch.Tensor


def batched_omp(
    D: torch.Tensor,
    X: torch.Tensor,
    n_nonzero: int,
    mask: torch.Tensor | None = None,
    tol: float | torch.Tensor | None = None,
) -> OMPResult:
    r"""Orthogonal matching pursuit for many signals at once, optionally with missing entries.

    Pati et al. 1993. For every signal :math:`x_n` (observed entries :math:`\Omega_n`), with atoms
    restricted to the observed entries :math:`d_k^{\Omega} = M_n d_k`, each step selects

    .. math::
        k^\star = \arg\max_{k \notin S} \frac{|\langle d_k^{\Omega}, r\rangle|}{\|d_k^{\Omega}\|},
        \qquad a_S = \arg\min_a \|M_n x_n - D^{\Omega}_S a\|_2^2,\qquad r = M_n x_n - D^{\Omega}_S a_S

    and stops after ``n_nonzero`` atoms, when :math:`\|r\|^2 \le` ``tol`` (if given), or when no
    atom correlates with the residual any more (linear dependence). Without a mask and with
    unit-norm atoms this is exactly scikit-learn's ``orthogonal_mp`` (same selections, same
    least-squares coefficients); the division by :math:`\|d_k^\Omega\|` only matters for atoms that
    are not unit norm on the observed entries. Least squares are re-solved each step from the
    normal equations (a tiny ridge, ~100 machine epsilons times the Gram diagonal, guards singular
    systems). Runs on any device; all signals advance together.

    Args:
        D: (F, K) dictionary, one atom per column.
        X: (N, F) signals, one per row.
        n_nonzero: maximum number of atoms per signal.
        mask: (N, F) 1 = observed, 0 = missing (the entry is ignored in the fit). Default: all.
        tol: maximum squared residual norm, a float or an (N,) tensor; None = fixed sparsity.

    Returns:
        :class:`OMPResult` ``(coef (N,K), n_active (N,), residual (N,))``.

    Examples:
        >>> D = torch.nn.functional.normalize(torch.randn(16, 32), dim=0)
        >>> x = 2.0 * D[:, 3] - 1.0 * D[:, 7]
        >>> res = batched_omp(D, x[None], n_nonzero=2)
        >>> res.coef[0, [3, 7]].round(decimals=4).tolist(), int(res.n_active[0])
        ([2.0, -1.0], 2)
    """
    if not isinstance(D, torch.Tensor) or D.ndim != 2:
        raise ShapeError(f"D must be a (F, K) tensor; got {getattr(D, 'shape', type(D))}.",
                         actual=tuple(D.shape) if hasattr(D, "shape") else None, expected="(F, K)")
    if not isinstance(X, torch.Tensor) or X.ndim != 2 or X.shape[1] != D.shape[0]:
        raise ShapeError(
            f"X must be (N, F) with F = D.shape[0] = {D.shape[0]}; got {tuple(getattr(X, 'shape', ()))}. "
            "Put one signal per row.",
            actual=tuple(X.shape) if hasattr(X, "shape") else None, expected=f"(N, {D.shape[0]})",
        )
    if mask is not None:
        check_same_shape(mask, X, "mask", "X")
    if not isinstance(n_nonzero, int) or n_nonzero < 1:
        raise DepthSRError(f"n_nonzero must be an int >= 1; got {n_nonzero!r}.")
    n, f = X.shape
    k_atoms = D.shape[1]
    n_nonzero = min(n_nonzero, f, k_atoms)
    D = D.to(X.dtype)
    eps = torch.finfo(X.dtype).eps
    tiny = torch.finfo(X.dtype).tiny

    if mask is None:
        Xm = X
        norms2 = D.square().sum(0).expand(n, k_atoms)  # (N, K)
    else:
        mask = mask.to(X.dtype)
        Xm = X * mask
        norms2 = mask @ D.square()  # (N, K) squared norms of the masked atoms
    inv_norm = torch.where(norms2 > 1e3 * eps * norms2.amax(1, keepdim=True).clamp_min(tiny),
                           norms2.clamp_min(tiny).rsqrt(), torch.zeros_like(norms2))  # (N, K)

    res2 = Xm.square().sum(1)  # (N,)
    # An atom whose correlation is at rounding level of the signal norm cannot reduce the residual.
    min_corr = 1e2 * eps * res2.sqrt()  # (N,)
    if tol is None:
        tol_t = None
        act = torch.arange(n, device=X.device)
    else:
        tol_t = torch.as_tensor(tol, dtype=X.dtype, device=X.device).expand(n)
        act = (res2 > tol_t).nonzero()[:, 0]
    # Only the signals still active are touched; a signal that stops keeps its buffers. All the
    # support slots of an active signal are in use, so no per-slot validity is needed.
    s_max = n_nonzero
    r = Xm.clone()  # (N, F)
    Ds = X.new_zeros(n, s_max, f)  # (N, S, F) selected atoms restricted to the observed entries
    G = X.new_zeros(n, s_max, s_max)  # (N, S, S) their Gram matrix, grown one row/column a step
    rhs = X.new_zeros(n, s_max)  # (N, S) their correlations with the signal
    acoef = X.new_zeros(n, s_max)  # (N, S) least-squares coefficients on the support
    support = torch.zeros(n, s_max, dtype=torch.long, device=X.device)  # (N, S)
    n_active = torch.zeros(n, dtype=torch.long, device=X.device)  # (N,)
    Dt = D.t()  # (K, F)
    for step in range(s_max):
        if act.numel() == 0:
            break
        corr = (r[act] @ D).mul_(inv_norm[act]).abs_()  # (n_a, K)
        if step > 0:
            corr.scatter_(1, support[act, :step], 0.0)  # never reselect an atom
        best, idx = corr.max(1)  # (n_a,)
        keep = (best > min_corr[act]) & (best > 0)
        act, idx = act[keep], idx[keep]
        if act.numel() == 0:
            break
        v = Dt[idx]  # (n_a, F)
        if mask is not None:
            v = v * mask[act]
        xa = Xm[act]  # (n_a, F)
        Ds[act, step] = v
        Dprev = Ds[act, : step + 1]  # (n_a, s, F)
        g = (Dprev @ v[..., None])[..., 0]  # (n_a, s) new Gram row
        G[act, step, : step + 1] = g
        G[act, : step + 1, step] = g
        rhs[act, step] = (v * xa).sum(1)
        Ga = G[act, : step + 1, : step + 1]  # (n_a, s, s)
        ridge = 1e2 * eps * torch.diagonal(Ga, dim1=1, dim2=2).amax(1).clamp_min(tiny)  # (n_a,)
        Ga = Ga + ridge[:, None, None] * torch.eye(step + 1, dtype=X.dtype, device=X.device)
        sol = torch.linalg.solve(Ga, rhs[act, : step + 1, None])[..., 0]  # (n_a, s)
        acoef[act, : step + 1] = sol
        support[act, step] = idx
        n_active[act] = step + 1
        ra = xa - (sol[:, None, :] @ Dprev)[:, 0]  # (n_a, F)
        r[act] = ra
        res2[act] = ra.square().sum(1)
        if tol_t is not None:
            act = act[res2[act] > tol_t[act]]
    coef = X.new_zeros(n, k_atoms).scatter_add(1, support, acoef)  # unused slots add 0 to atom 0
    return OMPResult(coef, n_active, res2)


def overcomplete_dct_dictionary(patch_size: int, n_atoms: int, dtype: torch.dtype = torch.float32,
                                device: torch.device | str | None = None) -> torch.Tensor:
    r"""Overcomplete separable DCT dictionary without the DC atom (the K-SVD initialisation).

    Atoms are :math:`\cos(\pi u (i + 1/2)/n_y) \cos(\pi v (j + 1/2)/n_x)` sampled on a
    ``patch_size`` grid for :math:`n_y n_x > K` frequencies, ordered by :math:`u + v`; the
    constant atom is left out (patches are mean-removed) and the first ``n_atoms`` are kept,
    each with unit norm.

    Args:
        patch_size: patch side p.
        n_atoms: number of atoms K.

    Returns:
        (p*p, K) dictionary with unit-norm columns.

    Examples:
        >>> overcomplete_dct_dictionary(8, 128).shape
        torch.Size([64, 128])
    """
    n1 = max(patch_size, math.ceil(math.sqrt(n_atoms + 1)))
    i = torch.arange(patch_size, dtype=torch.float64)
    u = torch.arange(n1, dtype=torch.float64)
    basis = torch.cos(math.pi * u[None, :] * (i[:, None] + 0.5) / n1)  # (p, n1)
    freqs = [(uu + vv, uu, vv) for uu in range(n1) for vv in range(n1) if (uu, vv) != (0, 0)]
    freqs.sort()
    cols = [torch.outer(basis[:, uu], basis[:, vv]).flatten() for _, uu, vv in freqs[:n_atoms]]
    D = torch.stack(cols, 1)  # (p*p, K)
    D = D - D.mean(0, keepdim=True)  # zero-mean atoms (exact for the sampled cosines with u, v > 0)
    D = torch.nn.functional.normalize(D, dim=0)
    return D.to(dtype=dtype, device=device)


def estimate_noise_sigma(depth: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    r"""Robust per-sample estimate of i.i.d. noise sigma from the Haar diagonal detail (the library's one
    estimator, :func:`torch_depth_sr.noise.estimate_noise_sigma` with ``method="haar"``).

    Donoho & Johnstone 1994: :math:`\hat\sigma = \mathrm{median}|HH| / 0.6745` with
    :math:`HH = (x_{00} - x_{01} - x_{10} + x_{11})/2` over non-overlapping 2x2 blocks whose four
    pixels are measured. Planes give HH = 0, so piecewise-planar depth is estimated well.

    Args:
        depth: (B,1,H,W) depth.
        mask: (B,1,H,W) 1 = measured; default ``depth > 0`` and finite.

    Returns:
        (B,) sigma estimates (0 where no complete 2x2 block exists).

    Examples:
        >>> g = torch.Generator().manual_seed(0)
        >>> d = 100 + 5 * torch.randn(1, 1, 64, 64, generator=g)
        >>> round(float(estimate_noise_sigma(d)[0]))
        5
    """
    _check_depth(depth)
    return _estimate_noise_sigma(depth, _resolve_mask(depth, mask), method="haar")


def _patch_starts(n: int, p: int, stride: int) -> list[int]:
    starts = list(range(0, n - p + 1, stride))
    if starts[-1] != n - p:
        starts.append(n - p)  # the last patch touches the border, so every pixel is covered
    return starts


def _ksvd_update(D: torch.Tensor, Y: torch.Tensor, A: torch.Tensor, gen: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """One sweep of approximate K-SVD (one power step per atom). Y (n,F), A (n,K), D (F,K)."""
    D = D.clone()
    A = A.clone()
    K = D.shape[1]
    for k in torch.randperm(K, generator=gen).tolist():
        I = A[:, k].nonzero()[:, 0]
        if I.numel() == 0:
            continue
        D[:, k] = 0.0
        g = A[I, k]  # (|I|,)
        YI, AI = Y[I], A[I]
        d = YI.t() @ g - D @ (AI.t() @ g)  # (F,) = E_I^T g
        nd = d.norm()
        if nd <= 0:
            continue
        d = d / nd
        g = YI @ d - AI @ (D.t() @ d)  # (|I|,) = E_I d
        D[:, k] = d
        A[I, k] = g
    return D, A


def _mod_update(D: torch.Tensor, Y: torch.Tensor, A: torch.Tensor) -> torch.Tensor:
    """Method of optimal directions: D = Y^T A (A^T A + eps I)^-1, columns renormalised."""
    K = D.shape[1]
    AtA = A.t() @ A + 1e-6 * torch.eye(K, dtype=A.dtype, device=A.device) * A.square().sum().clamp_min(1) / K
    Dn = torch.linalg.solve(AtA, A.t() @ Y).t()  # (F, K)
    used = A.abs().sum(0) > 0
    return torch.where(used[None], torch.nn.functional.normalize(Dn, dim=0), D)


def _replace_unused(D: torch.Tensor, Y: torch.Tensor, A: torch.Tensor, residual: torch.Tensor) -> torch.Tensor:
    """Atoms no sample uses are replaced by the worst-represented samples (normalised)."""
    unused = (A.abs().sum(0) == 0).nonzero()[:, 0]
    if unused.numel() == 0:
        return D
    worst = residual.argsort(descending=True)[: unused.numel()]
    new = torch.nn.functional.normalize(Y[worst] - Y[worst].mean(1, keepdim=True), dim=1).t()  # (F, u)
    ok = new.norm(dim=0) > 0
    D = D.clone()
    D[:, unused[ok]] = new[:, ok]
    return D


def _denoise_one(
    x: torch.Tensor,
    m: torch.Tensor,
    sigma: float,
    patch_size: int,
    n_atoms: int,
    sparsity: int,
    error_gain: float | None,
    stride: int,
    n_iter: int,
    n_train: int,
    method: str,
    data_weight: float,
    gen: torch.Generator,
    chunk: int,
) -> torch.Tensor:
    """Denoise one (H, W) image; returns (H, W) with zero-coverage pixels left at 0 (and weight 0)."""
    H, W = x.shape
    p = patch_size
    dev, dt = x.device, x.dtype
    ys = torch.tensor(_patch_starts(H, p, stride), device=dev)
    xs = torch.tensor(_patch_starts(W, p, stride), device=dev)
    off = (torch.arange(p, device=dev)[:, None] * W + torch.arange(p, device=dev)[None, :]).flatten()  # (F,)
    origin = (ys[:, None] * W + xs[None, :]).flatten()  # (N,)
    idx = origin[:, None] + off[None, :]  # (N, F) flat pixel indices of every patch
    xf = torch.where(m > 0, x, torch.zeros_like(x)).flatten()
    mf = m.flatten()
    P = xf[idx]  # (N, F)
    M = mf[idx]  # (N, F)
    n_obs = M.sum(1)  # (N,)
    mean = P.sum(1) / n_obs.clamp_min(1)  # (N,) mean over observed pixels
    Y = (P - mean[:, None]) * M  # (N, F)
    F_ = p * p
    tol_pix = None if error_gain is None else (error_gain * sigma) ** 2

    D = overcomplete_dct_dictionary(p, n_atoms, dtype=dt, device=dev)
    full = (n_obs == F_).nonzero()[:, 0]
    if full.numel() >= n_atoms and n_iter > 0:
        pick = torch.randperm(full.numel(), generator=gen)[:n_train].to(dev)
        Yt = Y[full[pick]]  # (n, F)
        tol_t = None if tol_pix is None else tol_pix * F_
        for _ in range(n_iter):
            res = batched_omp(D, Yt, sparsity, tol=tol_t)
            if method == "ksvd":
                D, _A = _ksvd_update(D, Yt, res.coef, gen)
            else:
                D = _mod_update(D, Yt, res.coef)
            D = _replace_unused(D, Yt, res.coef, res.residual)

    recon = torch.empty_like(Y)
    for s in range(0, Y.shape[0], chunk):
        sl = slice(s, s + chunk)
        tol_c = None if tol_pix is None else tol_pix * n_obs[sl]
        res = batched_omp(D, Y[sl], sparsity, mask=M[sl], tol=tol_c)
        recon[sl] = res.coef @ D.t() + mean[sl, None]  # (n, F)
    pw = (n_obs > 0).to(dt)[:, None].expand_as(recon)  # patches with no observed pixel carry no information
    num = torch.zeros(H * W, dtype=dt, device=dev).index_add_(0, idx.flatten(), (recon * pw).flatten())
    den = torch.zeros(H * W, dtype=dt, device=dev).index_add_(0, idx.flatten(), pw.flatten())
    if data_weight > 0:
        num = num + data_weight * mf * xf
        den = den + data_weight * mf
    out = torch.where(den > 0, num / den.clamp_min(1e-30), torch.zeros_like(num))
    return out.view(H, W), (den > 0).view(H, W)


def dictionary_denoise(
    depth: torch.Tensor,
    rgb: torch.Tensor | None = None,
    mask: torch.Tensor | None = None,
    patch_size: int = 8,
    n_atoms: int = 128,
    sparsity: int = 8,
    sigma: float | torch.Tensor | None = None,
    error_gain: float | None = 1.15,
    stride: int = 2,
    n_iter: int = 5,
    n_train: int = 4000,
    method: str = "ksvd",
    data_weight: float = 0.0,
    seed: int = 0,
    chunk_size: int = 16384,
) -> torch.Tensor:
    r"""Denoise and fill depth by sparse coding over a dictionary learned on the image itself.

    K-SVD denoising (Elad & Aharon, IEEE TIP 2006) with missing pixels masked out of the fit
    (Mairal, Elad & Sapiro, IEEE TIP 2008). Per image:

    1. Extract :math:`p \times p` patches :math:`R_i y` on a grid with step ``stride`` (plus the
       last row/column of patches so every pixel is covered) and remove from each its mean over
       the measured pixels, :math:`\mu_i`.
    2. Learn :math:`D` (``n_atoms`` unit atoms, initialised with an overcomplete DCT without DC)
       on up to ``n_train`` random fully-measured patches by ``n_iter`` rounds of sparse coding
       (:func:`batched_omp`) and a dictionary update: approximate K-SVD (Rubinstein et al. 2008,
       one power step per atom, ``method="ksvd"``) or MOD (Engan et al. 1999,
       :math:`D = Y A^\top (A A^\top)^{-1}`, ``method="mod"``); unused atoms are replaced by the
       worst-represented patches. With fewer fully-measured patches than atoms, the DCT is used.
    3. Code every patch with masked OMP, the atoms restricted to the measured pixels :math:`M_i`:

       .. math::
           \alpha_i = \arg\min_\alpha \|M_i (R_i y - \mu_i - D\alpha)\|_2^2 \ \text{s.t.}\
           \|\alpha\|_0 \le T \ \text{and stop once}\
           \|M_i (R_i y - \mu_i - D\alpha)\|_2^2 \le |M_i|\,(c\,\sigma)^2

       (``sparsity`` = :math:`T`, ``error_gain`` = :math:`c`; ``error_gain=None`` codes with
       exactly :math:`T` atoms).
    4. Average the overlapping reconstructions, optionally with the measured data:

       .. math::
           \hat x = \Big(\lambda M y + \sum_i R_i^\top (\mu_i + D\alpha_i)\Big) \Big/
                    \Big(\lambda M + \sum_i R_i^\top R_i\Big)

       (``data_weight`` = :math:`\lambda`, in units of "patches"; with ``stride`` s each pixel is
       covered by about :math:`(p/s)^2` patches).

    Missing pixels are predicted by the atoms from the measured part of each patch, so holes
    narrower than a patch are filled; pixels that no patch with a measured pixel covers are filled
    by a pull-push normalised-convolution pyramid. ``stride`` > 1 is what keeps this fast: the
    number of patches to code falls as :math:`1/s^2` (stride 1 is the textbook algorithm and about
    4x slower than the default stride 2). Results are deterministic for a given ``seed``, and the
    same for a sample alone or in a batch (the sampler is reseeded per sample).

    Args:
        depth: (B,1,H,W) depth, any units (defaults suit 8-bit disparity with noise sigma ~5).
        rgb: (B,3,H,W) colour; accepted for a uniform baseline interface and only shape-checked
            (the method uses depth alone).
        mask: (B,1,H,W) 1 = measured; default ``depth > 0`` and finite.
        patch_size: patch side p (H and W must be >= p).
        n_atoms: dictionary size K.
        sparsity: maximum atoms per patch T.
        sigma: noise sigma in depth units, float or (B,) tensor; None = estimated per image with
            :func:`estimate_noise_sigma`. Only used by the error-constrained stop.
        error_gain: c in the stopping rule (1.15 in Elad & Aharon); None = fixed sparsity.
        stride: patch grid step s (1 = all patches).
        n_iter: dictionary-learning rounds (0 = keep the DCT dictionary).
        n_train: number of training patches sampled per image.
        method: ``"ksvd"`` (approximate K-SVD) or ``"mod"``.
        data_weight: :math:`\lambda`, weight of the measured data in the final average.
        seed: seed of the training-patch sampling.
        chunk_size: patches coded per batch (memory bound).

    Returns:
        (B,1,H,W) denoised, hole-filled depth with the input's dtype and device.

    Examples:
        >>> g = torch.Generator().manual_seed(0)
        >>> yy, xx = torch.meshgrid(torch.arange(48.0), torch.arange(48.0), indexing="ij")
        >>> clean = (100 + 0.5 * xx + 40.0 * (yy > 20)).view(1, 1, 48, 48)
        >>> noisy = clean + 5 * torch.randn(clean.shape, generator=g)
        >>> out = dictionary_denoise(noisy, n_atoms=64, n_iter=2)
        >>> bool((out - clean).square().mean() < (noisy - clean).square().mean() / 2)
        True
    """
    _check_depth(depth)
    if rgb is not None:
        _check_rgb(rgb)
        check_same_hw(depth, rgb, "depth", "rgb")
    for name, v, lo in [("patch_size", patch_size, 2), ("n_atoms", n_atoms, 1), ("sparsity", sparsity, 1),
                        ("stride", stride, 1), ("n_iter", n_iter, 0), ("n_train", n_train, 1),
                        ("chunk_size", chunk_size, 1)]:
        if not isinstance(v, int) or v < lo:
            raise DepthSRError(f"{name} must be an int >= {lo}; got {v!r}.")
    if method not in ("ksvd", "mod"):
        raise DepthSRError(f"method must be 'ksvd' or 'mod'; got {method!r}.")
    if error_gain is not None and not error_gain > 0:
        raise DepthSRError(f"error_gain must be positive or None; got {error_gain!r}.")
    if data_weight < 0:
        raise DepthSRError(f"data_weight must be >= 0; got {data_weight!r}.")
    check_min_size(depth, "depth", patch_size, "patch_size x patch_size; use a smaller patch_size")
    b = depth.shape[0]
    m = _resolve_mask(depth, mask)
    if sigma is None:
        sig = estimate_noise_sigma(depth, m)
    else:
        sig = torch.as_tensor(sigma, dtype=depth.dtype, device=depth.device)
        if sig.ndim == 0:
            sig = sig.expand(b)
        if sig.ndim != 1 or sig.shape[0] != b:
            raise ShapeError(f"sigma must be a float, None, or a (B,)=({b},) tensor; got shape {tuple(sig.shape)}.",
                             actual=tuple(sig.shape), expected=f"() or ({b},)")
        if bool((sig < 0).any()):
            raise DepthSRError(f"sigma must be >= 0; got {sig.tolist()}.")
    outs, covered = [], []
    with torch.no_grad():
        for i in range(b):
            # Reseeded per sample, so that a sample's result does not depend on its batch.
            gen = torch.Generator().manual_seed(seed)
            o, c = _denoise_one(
                depth[i, 0], m[i, 0], float(sig[i]), patch_size, n_atoms, sparsity, error_gain, stride, n_iter,
                n_train, method, float(data_weight), gen, chunk_size,
            )
            outs.append(o)
            covered.append(c)
        if b == 0:
            return depth.clone()
        out = torch.stack(outs)[:, None]  # (B, 1, H, W)
        cov = torch.stack(covered)[:, None]
        if not bool(cov.all()):
            out = _pull_push_fill(out, cov.to(depth.dtype))
    return out


class DictionaryDenoise(nn.Module):
    r"""Module form of :func:`dictionary_denoise`; stores the settings only.

    Examples:
        >>> DictionaryDenoise(n_atoms=32, n_iter=1)(torch.rand(1, 1, 24, 24) + 1).shape
        torch.Size([1, 1, 24, 24])
    """

    def __init__(
        self,
        patch_size: int = 8,
        n_atoms: int = 128,
        sparsity: int = 8,
        sigma: float | torch.Tensor | None = None,
        error_gain: float | None = 1.15,
        stride: int = 2,
        n_iter: int = 5,
        n_train: int = 4000,
        method: str = "ksvd",
        data_weight: float = 0.0,
        seed: int = 0,
        chunk_size: int = 16384,
    ) -> None:
        super().__init__()
        self.patch_size = patch_size
        self.n_atoms = n_atoms
        self.sparsity = sparsity
        self.sigma = sigma
        self.error_gain = error_gain
        self.stride = stride
        self.n_iter = n_iter
        self.n_train = n_train
        self.method = method
        self.data_weight = data_weight
        self.seed = seed
        self.chunk_size = chunk_size

    def forward(
        self, depth: torch.Tensor, rgb: torch.Tensor | None = None, mask: torch.Tensor | None = None
    ) -> torch.Tensor:
        return dictionary_denoise(
            depth, rgb, mask, patch_size=self.patch_size, n_atoms=self.n_atoms, sparsity=self.sparsity,
            sigma=self.sigma, error_gain=self.error_gain, stride=self.stride, n_iter=self.n_iter,
            n_train=self.n_train, method=self.method, data_weight=self.data_weight, seed=self.seed,
            chunk_size=self.chunk_size,
        )

    def extra_repr(self) -> str:
        return (
            f"patch_size={self.patch_size}, n_atoms={self.n_atoms}, sparsity={self.sparsity}, sigma={self.sigma}, "
            f"error_gain={self.error_gain}, stride={self.stride}, n_iter={self.n_iter}, method={self.method!r}"
        )
