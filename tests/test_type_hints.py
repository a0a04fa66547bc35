"""Every public signature carries type hints (issue 10 item 6).

Public = a function or class of the package named in a module's ``__all__`` (a re-export counts as a name of
the module that defines it); for a class, its
methods (plain, static, class methods and property getters) whose names do not start with ``_``, plus
``__init__`` and ``__call__``. Each must annotate every parameter except ``self``/``cls``/``*args``/``**kwargs``,
and its return (``__init__`` excepted). The check reads the signatures only (``inspect``), so string
annotations (``from __future__ import annotations``) count and nothing is evaluated.
"""
import importlib
import inspect
import pkgutil

import pytest

import torch_depth_sr

MODULES = ["torch_depth_sr"] + sorted(m.name for m in pkgutil.walk_packages(torch_depth_sr.__path__, "torch_depth_sr."))

# Signatures allowed to lack hints, keys "module:qualified name". Empty: a new public function has hints from
# the start.
ALLOWED_MISSING: set[str] = set()  # every public signature is annotated; keep it so


def _methods(cls: type):
    """``(name, function)`` of the public methods a class defines itself (inherited ones are checked at home)."""
    for name, value in vars(cls).items():
        if name.startswith("_") and name not in ("__init__", "__call__"):
            continue
        if isinstance(value, (staticmethod, classmethod)):
            value = value.__func__
        elif isinstance(value, property):
            value = value.fget
        # a Protocol's __init__ is typing's, not written here
        if inspect.isfunction(value) and value.__module__.startswith("torch_depth_sr"):
            yield name, value


def public_functions(module_name: str):
    """``("home module:qualified name", function)`` of every public function and method named by a module."""
    mod = importlib.import_module(module_name)
    for name in mod.__all__:
        obj = getattr(mod, name)
        home = getattr(obj, "__module__", None) or ""
        if not home.startswith("torch_depth_sr"):
            continue  # constants, and names taken from other libraries
        if inspect.isfunction(obj):
            yield f"{home}:{obj.__qualname__}", obj
        elif inspect.isclass(obj):
            for meth, fn in _methods(obj):
                yield f"{home}:{obj.__qualname__}.{meth}", fn


def missing_hints(fn) -> list[str]:
    """What ``fn``'s signature leaves unannotated: parameter names, and ``"return"``."""
    sig = inspect.signature(fn)
    gaps = [p.name for p in sig.parameters.values()
            if p.name not in ("self", "cls") and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
            and p.annotation is inspect.Parameter.empty]
    if sig.return_annotation is inspect.Signature.empty and fn.__name__ != "__init__":
        gaps.append("return")
    return gaps


def _all_missing() -> dict[str, list[str]]:
    return {key: gaps for m in MODULES for key, fn in public_functions(m) if (gaps := missing_hints(fn))}


def test_every_public_signature_is_annotated():
    unexpected = {k: v for k, v in _all_missing().items() if k not in ALLOWED_MISSING}
    assert not unexpected, "public signatures without type hints (annotate them):\n" + "\n".join(
        f"  {k}: {', '.join(v)}" for k, v in sorted(unexpected.items()))


def test_allow_list_holds_only_what_is_still_missing():
    stale = sorted(ALLOWED_MISSING - set(_all_missing()))
    assert not stale, f"annotated now (or gone): delete from ALLOWED_MISSING: {stale}"


def _example_unannotated(x, y=1):
    return x


def _example_annotated(self, x: int, *args, y: str = "", **kwargs) -> None:
    return None


@pytest.mark.parametrize("fn, gaps", [(_example_unannotated, ["x", "y", "return"]), (_example_annotated, [])])
def test_the_check_sees_missing_hints(fn, gaps):
    assert missing_hints(fn) == gaps
