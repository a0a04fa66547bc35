"""torch_depth_sr: colour-guided depth-map restoration as an unrolled PyTorch module.

TV + nonlocal self-similarity + sparse outliers with singular-pixel detection, solved by
half-quadratic splitting; see ``DepthRestorer`` and ``restore_depth``.
"""
from . import _openmp  # noqa: F401  (first: it chooses how long torch's OpenMP threads spin, before torch loads)
from .block_matching import BlockMatches, block_match, gather_neighbors, refine_matches
from .config import RestorerConfig
from .errors import DepthSRError, DTypeError, InvalidDepthError, ModelFileError, ParameterError, ShapeError
from .fill import fill_holes
from .metrics import bad_pixel_rate, mae, rmse
from .model import DepthRestorer, RestorationResult, restore_depth
from .noise import estimate_noise_sigma
from .nonlocal_prior import nonlocal_gradient, nonlocal_value_prior
from .recordings import discover_recordings, restore_dataset
from .shrinkage import group_soft_threshold, soft_threshold
from .singular import detect_singular
from .solvers.cg import conjugate_gradient
from .stream import StreamRestorer
from .transforms import RestoreDepth

__version__ = "0.1.0"

# the unfold oracle block_matching.block_match_reference is for tests and stays in its module
__all__ = [
    "BlockMatches",
    "DTypeError",
    "DepthRestorer",
    "DepthSRError",
    "InvalidDepthError",
    "ModelFileError",
    "ParameterError",
    "RestorationResult",
    "RestoreDepth",
    "RestorerConfig",
    "ShapeError",
    "StreamRestorer",
    "__version__",
    "bad_pixel_rate",
    "block_match",
    "conjugate_gradient",
    "detect_singular",
    "discover_recordings",
    "estimate_noise_sigma",
    "fill_holes",
    "gather_neighbors",
    "group_soft_threshold",
    "mae",
    "nonlocal_gradient",
    "nonlocal_value_prior",
    "refine_matches",
    "restore_dataset",
    "restore_depth",
    "rmse",
    "soft_threshold",
]
