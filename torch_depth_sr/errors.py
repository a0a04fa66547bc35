"""Exceptions raised by torch_depth_sr.

Every error says what arrived, what is allowed and, where there is one, the fix.
"""


class DepthSRError(ValueError):
    """Base class of the library's input errors (a ``ValueError``)."""


class ShapeError(DepthSRError):
    """A tensor or array has a shape the function cannot accept."""


class DTypeError(DepthSRError, TypeError):
    """A tensor or array has a dtype the function cannot accept."""


class InvalidDepthError(DepthSRError):
    """Depth values cannot be used (all missing, negative, infinite)."""


__all__ = ["DepthSRError", "DTypeError", "InvalidDepthError", "ShapeError"]
