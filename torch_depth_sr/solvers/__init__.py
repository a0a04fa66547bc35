"""Linear solvers: batched preconditioned CG, the DCT Neumann solver/preconditioner, and CG with an
implicit-differentiation backward."""
from .cg import CGResult, conjugate_gradient
from .dct import NeumannPreconditioner, dct2, dct_matrix, idct2, neumann_eigenvalues, solve_neumann
from .implicit import cg_solve

__all__ = [
    "CGResult",
    "NeumannPreconditioner",
    "cg_solve",
    "conjugate_gradient",
    "dct2",
    "dct_matrix",
    "idct2",
    "neumann_eigenvalues",
    "solve_neumann",
]
