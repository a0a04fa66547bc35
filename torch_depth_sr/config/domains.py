"""Domains of the settings: small checkers that raise :class:`~torch_depth_sr.errors.ParameterError` naming the
setting (``"block_matching.k"``), the value and what is allowed."""
from __future__ import annotations

import math
from numbers import Integral, Real
from typing import Any, Callable

from ..errors import ParameterError

__all__ = ["Check", "boolean", "choice", "int_tuple", "integer", "is_int", "is_real", "non_negative", "optional",
           "positive", "real", "str_tuple"]

Check = Callable[[str, Any], None]


def is_int(v: Any) -> bool:
    return isinstance(v, Integral) and not isinstance(v, bool)


def is_real(v: Any) -> bool:
    return isinstance(v, Real) and not isinstance(v, bool)


def integer(lo: int, odd: bool = False) -> Check:
    allowed = f"an {'odd ' if odd else ''}int >= {lo}"

    def check(name: str, v: Any) -> None:
        if not is_int(v) or v < lo or (odd and v % 2 == 0):
            hint = "The block is centred on the pixel, so its size is odd." if odd and is_int(v) and v >= lo else ""
            raise ParameterError(name, v, allowed, hint)
    return check


def real(lo: float, hi: float = math.inf, lo_open: bool = True, hi_open: bool = False) -> Check:
    left, right = "(" if lo_open else "[", ")" if hi_open or hi == math.inf else "]"
    allowed = f"a finite number in {left}{lo:g}, {hi:g}{right}"
    if hi == math.inf:
        allowed = f"a finite number {'>' if lo_open else '>='} {lo:g}"

    def check(name: str, v: Any) -> None:
        ok = is_real(v) and math.isfinite(v)
        ok = ok and (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
        if not ok:
            raise ParameterError(name, v, allowed)
    return check


positive = real(0.0)
non_negative = real(0.0, lo_open=False)


def boolean(name: str, v: Any) -> None:
    if not isinstance(v, bool):
        raise ParameterError(name, v, "True or False")


def choice(*options: str) -> Check:
    def check(name: str, v: Any) -> None:
        if not isinstance(v, str) or v not in options:
            raise ParameterError(name, v, f"one of {list(options)}")
    return check


def optional(inner: Check) -> Check:
    """``inner``, or None (the setting is off)."""
    def check(name: str, v: Any) -> None:
        if v is not None:
            inner(name, v)
    return check


def int_tuple(lo: int, example: str) -> Check:
    def check(name: str, v: Any) -> None:
        if not isinstance(v, tuple) or not all(is_int(i) and i >= lo for i in v):
            raise ParameterError(name, v, f"a tuple or list of ints >= {lo}, e.g. {example}")
    return check


def str_tuple(*options: str) -> Check:
    def check(name: str, v: Any) -> None:
        if not isinstance(v, tuple) or not all(isinstance(i, str) and i in options for i in v) or len(set(v)) != len(v):
            raise ParameterError(name, v, f"a tuple of distinct names out of {list(options)}, e.g. {options}")
    return check
