"""Exceptions raised by torch_depth_sr.

Every error says what arrived, what is allowed and, where there is one, the fix.
"""
from __future__ import annotations

from typing import Any, Optional


class DepthSRError(ValueError):
    """Base class of the library's input errors (a ``ValueError``)."""


class ShapeError(DepthSRError):
    """A tensor or array has a shape the function cannot accept.

    Attributes:
        actual: the shape that arrived (a tuple), when the raiser knew it.
        expected: what is allowed, as text (e.g. ``"(B,1,H,W)"``), when the raiser stated it.
    """

    def __init__(self, message: str, actual: Optional[tuple] = None, expected: Optional[str] = None) -> None:
        super().__init__(message)
        self.actual, self.expected = actual, expected


class DTypeError(DepthSRError, TypeError):
    """A tensor or array has a dtype the function cannot accept."""


class InvalidDepthError(DepthSRError):
    """Depth values cannot be used (all missing, negative, infinite)."""


class ParameterError(DepthSRError):
    """A parameter (a :class:`~torch_depth_sr.config.RestorerConfig` field or a call argument) is out of its domain.

    Attributes:
        name: the parameter, e.g. ``"lam"`` or ``"noise_sigma"``.
        got: the value that arrived.
        allowed: what is allowed, in words (``"a finite number > 0"``).
    """

    def __init__(self, name: str, got: Any, allowed: str, hint: str = "") -> None:
        self.name, self.got, self.allowed, self.hint = name, got, allowed, hint
        shown = repr(got)
        shown = shown if len(shown) <= 80 else shown[:77] + "..."
        super().__init__(f"{name} must be {allowed}; got {shown}." + (f" {hint}" if hint else ""))

    def __reduce__(self):  # picklable (DataLoader workers send errors to the main process)
        return (type(self), (self.name, self.got, self.allowed, self.hint))


class ModelFileError(DepthSRError):
    """A saved model (``config.json``, ``state_dict.pt``) is missing, unreadable or not what :meth:`save` writes.

    Attributes:
        path: the file concerned.
    """

    def __init__(self, path: Any, message: str) -> None:
        self.path, self.message = path, message
        super().__init__(f"{path}: {message}")

    def __reduce__(self):
        return (type(self), (self.path, self.message))


class UsageError(DepthSRError):
    """Arguments that cannot work: a missing file, an unknown format, an output that would replace an input.

    The command line reports it with exit status 2, where it can before anything is read or written.
    """


def describe_error(e: BaseException) -> str:
    """One line for an exception: the library's message, or the OS's with the file, or the type and message."""
    if isinstance(e, DepthSRError):
        text = str(e)
    elif isinstance(e, OSError) and e.strerror:
        where = f" '{e.filename}'" if e.filename else ""
        text = f"{e.strerror}:{where}" if where else e.strerror
    else:
        text = f"{type(e).__name__}: {e} (unexpected; rerun with --debug for the traceback)"
    return single_line(text)


def single_line(text: object) -> str:
    """``text`` with every run of whitespace, newlines included, folded to one space."""
    return " ".join(str(text).split())


__all__ = ["DTypeError", "describe_error", "single_line", "DepthSRError", "InvalidDepthError", "ModelFileError", "ParameterError", "ShapeError",
           "UsageError"]
