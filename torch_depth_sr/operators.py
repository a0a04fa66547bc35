r"""Linear operators of the model: the discrete gradient ``D``, its adjoint ``Dᵀ``, the Neumann
Laplacian ``DᵀD`` and the area-downsampling degradation ``K`` with its adjoint ``Kᵀ``.

Every operator works on batched ``(B, C, H, W)`` tensors of any floating dtype and device, never
modifies its input, and ships with its exact adjoint. :func:`dot_test` checks adjointness
numerically:

.. math::

    \langle A u, v \rangle = \langle u, A^\top v \rangle .

Functions hold the maths; the classes :class:`Gradient`, :class:`Identity`,
:class:`AreaDownsample` and :class:`BicubicDownsample` only store settings and forward to them
(``.forward``, ``.adjoint`` and ``.normal`` = ``AᵀA``). The last three are :class:`Degradation`\ s:
the model builds one per forward (:func:`degradation_operator`) and hands it to every layer.
"""
from __future__ import annotations

import functools
from typing import Sequence

import torch
import torch.nn.functional as F

from ._checks import check_4d, check_divisible, check_floating
from .errors import DepthSRError, ShapeError

__all__ = [
    "BicubicDownsample",
    "AreaDownsample",
    "DEGRADATIONS",
    "Degradation",
    "Gradient",
    "Identity",
    "LinearOperator",
    "area_downsample",
    "area_downsample_adjoint",
    "degradation_operator",
    "dot_test",
    "grad",
    "grad_adjoint",
    "laplacian",
    "laplacian_diagonal",
]


# --------------------------------------------------------------------------------------------
# Gradient D, adjoint Dᵀ, Laplacian DᵀD (Neumann boundary)
# --------------------------------------------------------------------------------------------
def _grad(x: torch.Tensor) -> torch.Tensor:
    dh = F.pad(x[..., :, 1:] - x[..., :, :-1], (0, 1))  # (B, C, H, W), last column 0
    dv = F.pad(x[..., 1:, :] - x[..., :-1, :], (0, 0, 0, 1))  # (B, C, H, W), last row 0
    return torch.cat([dh, dv], dim=1)  # (B, 2C, H, W)


def _grad_adjoint(p: torch.Tensor) -> torch.Tensor:
    c = p.shape[1] // 2
    ph = p[:, :c, :, :-1]  # (B, C, H, W-1); the last column is never produced by D
    pv = p[:, c:, :-1, :]  # (B, C, H-1, W)
    # (Dhᵀ p)_j = p_{j-1} - p_j with p_{-1} = p_{W-1} = 0
    return (F.pad(ph, (1, 0)) - F.pad(ph, (0, 1))) + (F.pad(pv, (0, 0, 1, 0)) - F.pad(pv, (0, 0, 0, 1)))


def grad(x: torch.Tensor) -> torch.Tensor:
    r"""Discrete gradient ``D``: forward differences with a Neumann (zero-flux) boundary.

    .. math::

        (D_h x)_{i,j} = x_{i,j+1} - x_{i,j}, \qquad (D_v x)_{i,j} = x_{i+1,j} - x_{i,j},

    with ``(D_h x)_{i,W-1} = 0`` and ``(D_v x)_{H-1,j} = 0``.

    Args:
        x: image of shape ``(B, C, H, W)`` (the model uses ``C = 1``).

    Returns:
        ``(B, 2C, H, W)``: channels ``0..C-1`` are the horizontal differences, channels
        ``C..2C-1`` the vertical ones (for ``C = 1``: channel 0 horizontal, channel 1 vertical).

    Examples:
        >>> x = torch.tensor([[[[0., 1., 3.], [2., 2., 2.]]]])
        >>> grad(x)
        tensor([[[[ 1.,  2.,  0.],
                  [ 0.,  0.,  0.]],
        <BLANKLINE>
                 [[ 2.,  1., -1.],
                  [ 0.,  0.,  0.]]]])
    """
    check_4d(x, "x")
    check_floating(x, "x")
    return _grad(x)


def grad_adjoint(p: torch.Tensor) -> torch.Tensor:
    r"""Exact adjoint ``Dᵀ`` of :func:`grad` (the negative divergence).

    ``⟨D x, p⟩ = ⟨x, Dᵀ p⟩`` for all ``x, p``. Entries of ``p`` in the last column (horizontal part)
    and last row (vertical part) do not influence the result, because ``D`` always writes 0 there.

    Args:
        p: field of shape ``(B, 2C, H, W)`` laid out like the output of :func:`grad`.

    Returns:
        ``(B, C, H, W)``.

    Examples:
        >>> x = torch.randn(2, 1, 5, 6, dtype=torch.float64)
        >>> p = torch.randn(2, 2, 5, 6, dtype=torch.float64)
        >>> bool(torch.isclose((grad(x) * p).sum(), (x * grad_adjoint(p)).sum()))
        True
    """
    check_4d(p, "p")
    check_floating(p, "p")
    if p.shape[1] % 2 != 0:
        raise ShapeError(
            f"p must have an even number of channels (B,2C,H,W): C horizontal then C vertical differences, "
            f"as returned by grad(); got shape {tuple(p.shape)}.", actual=tuple(p.shape), expected="(B,2C,H,W)"
        )
    return _grad_adjoint(p)


def _laplacian(x: torch.Tensor) -> torch.Tensor:
    return _grad_adjoint(_grad(x))


def laplacian(x: torch.Tensor) -> torch.Tensor:
    r"""Neumann Laplacian ``DᵀD x`` (5-point stencil, positive semidefinite).

    In the interior ``(DᵀD x)_{i,j} = 4 x_{i,j} - x_{i-1,j} - x_{i+1,j} - x_{i,j-1} - x_{i,j+1}``;
    at the border only the neighbours inside the image count (the centre weight is their number).
    Its null space is the constant images; its eigenvalues are
    ``(2 - 2 cos(π k / H)) + (2 - 2 cos(π l / W))`` with DCT-II eigenvectors
    (see :func:`torch_depth_sr.solvers.dct.solve_neumann`).

    Args:
        x: ``(B, C, H, W)``.

    Returns:
        ``(B, C, H, W)``.

    Examples:
        >>> x = torch.zeros(1, 1, 3, 3); x[0, 0, 1, 1] = 1.0
        >>> laplacian(x)[0, 0]
        tensor([[ 0., -1.,  0.],
                [-1.,  4., -1.],
                [ 0., -1.,  0.]])
    """
    check_4d(x, "x")
    check_floating(x, "x")
    return _laplacian(x)


def laplacian_diagonal(like: torch.Tensor) -> torch.Tensor:
    """The diagonal of :func:`laplacian` for images of ``like``'s size, dtype and device, ``(1, 1, H, W)``: each
    pixel's count of in-image 4-neighbours (4 inside, 3 on an edge, 2 at a corner).

    Examples:
        >>> laplacian_diagonal(torch.zeros(1, 1, 3, 4))[0, 0]
        tensor([[2., 3., 3., 2.],
                [3., 4., 4., 3.],
                [2., 3., 3., 2.]])
    """
    h, w = like.shape[-2:]
    return _laplacian_diagonal(h, w, like.dtype, like.device)


@functools.lru_cache(maxsize=8)
def _laplacian_diagonal(h: int, w: int, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    rows = torch.full((h,), 2.0, dtype=dtype, device=device)
    cols = torch.full((w,), 2.0, dtype=dtype, device=device)
    rows[0] -= 1
    rows[-1] -= 1
    cols[0] -= 1
    cols[-1] -= 1
    return (rows[:, None] + cols[None, :]).view(1, 1, h, w)


# --------------------------------------------------------------------------------------------
# Area downsampling K and its adjoint Kᵀ
# --------------------------------------------------------------------------------------------
def _check_factor(s: int) -> int:
    if isinstance(s, bool) or not isinstance(s, int) or s < 1:
        raise DepthSRError(f"the downsampling factor s must be an int >= 1; got {s!r}.")
    return s


def area_downsample(x: torch.Tensor, s: int) -> torch.Tensor:
    r"""Area downsampling ``K``: the mean of every non-overlapping ``s × s`` block.

    .. math:: (K x)_{i,j} = \frac{1}{s^2} \sum_{a,b=0}^{s-1} x_{s i + a,\, s j + b}

    Args:
        x: high-resolution image ``(B, C, H, W)``; ``H`` and ``W`` must be divisible by ``s``.
        s: integer factor ``>= 1``.

    Returns:
        ``(B, C, H / s, W / s)``.

    Raises:
        ShapeError: if ``H`` or ``W`` is not a multiple of ``s``.

    Examples:
        >>> area_downsample(torch.arange(16.).reshape(1, 1, 4, 4), 2)
        tensor([[[[ 2.5000,  4.5000],
                  [10.5000, 12.5000]]]])
    """
    check_4d(x, "x")
    check_floating(x, "x")
    s = _check_factor(s)
    check_divisible(x, "x", s, "area_downsample")
    if s == 1:
        return x.clone()
    return F.avg_pool2d(x, kernel_size=s, stride=s)  # (B, C, H/s, W/s)


def area_downsample_adjoint(v: torch.Tensor, s: int) -> torch.Tensor:
    r"""Exact adjoint ``Kᵀ`` of :func:`area_downsample`: replicate each pixel ``s × s`` times and
    divide by ``s²``.

    Note ``K Kᵀ = I / s²`` and ``KᵀK`` is the block-averaging projector divided by ``s²``.

    Args:
        v: low-resolution image ``(B, C, h, w)``.
        s: integer factor ``>= 1``.

    Returns:
        ``(B, C, s h, s w)``.

    Examples:
        >>> area_downsample_adjoint(torch.tensor([[[[4.]]]]), 2)
        tensor([[[[1., 1.],
                  [1., 1.]]]])
    """
    check_4d(v, "v")
    check_floating(v, "v")
    s = _check_factor(s)
    if s == 1:
        return v.clone()
    # nearest-neighbour upsampling by an integer factor replicates each pixel exactly (checked against
    # repeat_interleave for s <= 16 up to 4000 px); its backward is the one the model always used, so training
    # gradients stay bit-identical
    up = F.interpolate(v, scale_factor=s, mode="nearest")  # (B, C, s h, s w)
    return up / (s * s)


# --------------------------------------------------------------------------------------------
# Operator classes
# --------------------------------------------------------------------------------------------
class LinearOperator:
    """Base class: a linear map with ``forward``, ``adjoint`` and ``normal`` (``AᵀA``).

    Calling the object applies ``forward``. Subclasses store settings only; the maths lives in
    the module-level functions.
    """

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # pragma: no cover - abstract
        raise NotImplementedError

    def adjoint(self, v: torch.Tensor) -> torch.Tensor:  # pragma: no cover - abstract
        raise NotImplementedError

    def normal(self, x: torch.Tensor) -> torch.Tensor:
        """``AᵀA x``."""
        return self.adjoint(self.forward(x))

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        return self.forward(x)

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class Gradient(LinearOperator):
    """The discrete gradient ``D`` (:func:`grad`); ``adjoint`` is :func:`grad_adjoint` and
    ``normal`` the Neumann Laplacian :func:`laplacian`.

    Examples:
        >>> D = Gradient()
        >>> D(torch.zeros(2, 1, 4, 5)).shape
        torch.Size([2, 2, 4, 5])
        >>> dot_test(D, (2, 1, 4, 5), (2, 2, 4, 5)) < 1e-12
        True
    """

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return grad(x)

    def adjoint(self, v: torch.Tensor) -> torch.Tensor:
        return grad_adjoint(v)

    def normal(self, x: torch.Tensor) -> torch.Tensor:
        return laplacian(x)


class Degradation(LinearOperator):
    r"""A degradation ``K`` from the output grid to the observation grid: the model's task.

    The restorer solves :math:`\min_x \tfrac12\|Q\odot(y-Kx)\|^2 + \dots`; every layer uses
    ``K``, ``Kᵀ`` and the two properties below, never the task's name or factor.

    Attributes:
        scale: the integer ratio ``s`` of the output grid to the observation grid (1: same grid). An
            observation pixel covers ``s × s`` output pixels, and ``KᵀK`` maps a constant image to
            ``1/s²`` of it (exactly for area averaging; away from the border for bicubic), which the
            preconditioner uses.
    """

    scale: int = 1

    @property
    def is_identity(self) -> bool:
        """Whether the observation grid is the output grid and ``K = I``: only then can a per-pixel quantity of
        the observation (the trusted set ``Q``, a measurement) be compared with the estimate pixel by pixel."""
        return False


class Identity(Degradation):
    """The identity ``K = I`` (denoising, the paper's setting). Returns its input unchanged
    (the same tensor object, no copy).

    Examples:
        >>> x = torch.ones(1, 1, 2, 2)
        >>> Identity()(x) is x
        True
        >>> Identity().is_identity, Identity().scale
        (True, 1)
    """

    @property
    def is_identity(self) -> bool:
        return True

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x

    def adjoint(self, v: torch.Tensor) -> torch.Tensor:
        return v

    def normal(self, x: torch.Tensor) -> torch.Tensor:
        return x


class AreaDownsample(Degradation):
    """Area downsampling by an integer factor ``s`` (:func:`area_downsample`), the degradation
    ``K`` of guided super-resolution; ``adjoint`` is :func:`area_downsample_adjoint`.

    Args:
        s: integer factor ``>= 1``.

    Examples:
        >>> K = AreaDownsample(2)
        >>> K(torch.ones(1, 1, 4, 6)).shape
        torch.Size([1, 1, 2, 3])
        >>> dot_test(K, (1, 1, 4, 6), (1, 1, 2, 3)) < 1e-12
        True
    """

    def __init__(self, s: int) -> None:
        self.s = _check_factor(s)

    @property
    def scale(self) -> int:
        return self.s

    @property
    def is_identity(self) -> bool:
        return self.s == 1

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return area_downsample(x, self.s)

    def adjoint(self, v: torch.Tensor) -> torch.Tensor:
        return area_downsample_adjoint(v, self.s)

    def __repr__(self) -> str:
        return f"AreaDownsample(s={self.s})"


@functools.lru_cache(maxsize=32)
def _bicubic_matrix(n: int, s: int, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    """The ``(n/s, n)`` matrix of the 1-D antialiased bicubic resize, shared by every operator (the model builds
    one per forward)."""
    # resizing the rows of the identity gives the matrix itself (the columns keep their size: torch's
    # width-1 images take another path, which does not match the 2-D resize)
    eye = torch.eye(n, dtype=torch.float64, device=device)[None, None]
    a = torch.nn.functional.interpolate(eye, size=(n // s, n), mode="bicubic", antialias=True, align_corners=False)
    return a[0, 0].contiguous().to(dtype)


class BicubicDownsample(Degradation):
    """Antialiased bicubic downsampling by an integer factor ``s``: the degradation of the guided
    super-resolution protocol of DKN/FDSR/DCTNet (Pillow's bicubic resize, which torch's
    ``interpolate(mode="bicubic", antialias=True)`` reproduces).

    The resize is separable, so ``K x = A_h x A_wᵀ`` with two small matrices built once per size by
    resizing the identity; the adjoint is ``A_hᵀ v A_w``, exact (dot-tested) and cheap.

    Examples:
        >>> K = BicubicDownsample(2)
        >>> K(torch.ones(1, 1, 8, 6)).shape
        torch.Size([1, 1, 4, 3])
        >>> dot_test(K, (1, 1, 8, 6), (1, 1, 4, 3)) < 1e-12
        True
    """

    def __init__(self, s: int) -> None:
        self.s = _check_factor(s)

    @property
    def scale(self) -> int:
        return self.s

    def _matrix(self, n: int, device, dtype) -> torch.Tensor:
        return _bicubic_matrix(n, self.s, torch.device(device), dtype)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        check_divisible(x, "x", self.s, f"BicubicDownsample(s={self.s})")
        h, w = x.shape[-2:]
        a_h, a_w = self._matrix(h, x.device, x.dtype), self._matrix(w, x.device, x.dtype)
        return a_h @ x @ a_w.T

    def adjoint(self, v: torch.Tensor) -> torch.Tensor:
        h, w = v.shape[-2] * self.s, v.shape[-1] * self.s
        a_h, a_w = self._matrix(h, v.device, v.dtype), self._matrix(w, v.device, v.dtype)
        return a_h.T @ v @ a_w

    def __repr__(self) -> str:
        return f"BicubicDownsample(s={self.s})"


DEGRADATIONS = ("area", "bicubic")


def degradation_operator(kind: str, s: int) -> Degradation:
    """The degradation of a task: :class:`Identity` for ``s = 1`` (denoising, whatever ``kind``), else
    :class:`AreaDownsample` (``kind="area"``) or :class:`BicubicDownsample` (``"bicubic"``) by ``s``.

    Examples:
        >>> degradation_operator("area", 1), degradation_operator("bicubic", 4)
        (Identity(), BicubicDownsample(s=4))
    """
    s = _check_factor(s)
    if kind not in DEGRADATIONS:
        raise DepthSRError(f"degradation={kind!r}; allowed are {list(DEGRADATIONS)}.")
    if s == 1:
        return Identity()
    return AreaDownsample(s) if kind == "area" else BicubicDownsample(s)


def dot_test(
    op: LinearOperator,
    x_shape: Sequence[int],
    y_shape: Sequence[int],
    dtype: torch.dtype = torch.float64,
    device: torch.device | str | None = None,
    generator: torch.Generator | None = None,
) -> float:
    r"""Dot test of an operator against its adjoint.

    Draws random ``u`` of shape ``x_shape`` and ``v`` of shape ``y_shape`` and returns the relative
    discrepancy

    .. math:: \frac{|\langle A u, v\rangle - \langle u, A^\top v\rangle|}
                   {\max(|\langle A u, v\rangle|, |\langle u, A^\top v\rangle|, \epsilon)} .

    A correct adjoint gives about machine precision (``< 1e-12`` in float64).

    Args:
        op: object with ``forward`` and ``adjoint``.
        x_shape: input shape of ``op.forward``.
        y_shape: output shape of ``op.forward`` (input shape of ``op.adjoint``).
        dtype: floating dtype of the random vectors (float64 for tight tolerances).
        device: device of the random vectors (default CPU).
        generator: optional CPU ``torch.Generator`` for reproducibility.

    Returns:
        the relative discrepancy as a Python float.

    Raises:
        ShapeError: if ``op.forward`` / ``op.adjoint`` do not produce ``y_shape`` / ``x_shape``.

    Examples:
        >>> dot_test(Gradient(), (1, 1, 8, 8), (1, 2, 8, 8)) < 1e-12
        True
    """
    u = torch.randn(tuple(x_shape), dtype=dtype, generator=generator).to(device)
    v = torch.randn(tuple(y_shape), dtype=dtype, generator=generator).to(device)
    au = op.forward(u)
    atv = op.adjoint(v)
    if tuple(au.shape) != tuple(y_shape):
        raise ShapeError(f"{op!r}.forward maps {tuple(x_shape)} to {tuple(au.shape)}, not to y_shape {tuple(y_shape)}.",
                         actual=tuple(au.shape), expected=str(tuple(y_shape)))
    if tuple(atv.shape) != tuple(x_shape):
        raise ShapeError(
            f"{op!r}.adjoint maps {tuple(y_shape)} to {tuple(atv.shape)}, not to x_shape {tuple(x_shape)}.",
            actual=tuple(atv.shape), expected=str(tuple(x_shape)),
        )
    lhs = (au * v).sum().item()
    rhs = (u * atv).sum().item()
    eps = torch.finfo(dtype).tiny
    return abs(lhs - rhs) / max(abs(lhs), abs(rhs), eps)
