"""torch_depth_sr: colour-guided depth-map restoration as an unrolled PyTorch module.

TV + nonlocal self-similarity + sparse outliers with singular-pixel detection, solved by
half-quadratic splitting; see ``DepthRestorer`` and ``restore_depth``.
"""
from .block_matching import BlockMatches, block_match, block_match_reference
from .config import RestorerConfig
from .errors import DepthSRError, DTypeError, InvalidDepthError, ModelFileError, ParameterError, ShapeError
from .fill import fill_holes
from .model import DepthRestorer, RestorationResult, restore_depth
from .noise import estimate_noise_sigma

__version__ = "0.1.0"

__all__ = [
    "BlockMatches",
    "DTypeError",
    "DepthRestorer",
    "DepthSRError",
    "InvalidDepthError",
    "ModelFileError",
    "ParameterError",
    "RestorationResult",
    "RestorerConfig",
    "ShapeError",
    "__version__",
    "block_match",
    "block_match_reference",
    "estimate_noise_sigma",
    "fill_holes",
    "restore_depth",
]
