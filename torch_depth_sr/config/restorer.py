"""The restorer's settings, :class:`RestorerConfig`: a few top-level choices and one settings group per part of the
model (:mod:`.groups`); an optional group set to ``None`` switches its step off. Version 2; version-1 files (one
flat object of 80 fields, written before 2026-12-03) convert on load (:mod:`.version1`)."""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Optional

from ..errors import ModelFileError, ParameterError
from ..precision import NETWORK_PRECISIONS
from .domains import choice, integer, str_tuple
from .version1 import FLAT_FIELDS, version1_settings
from .groups import (BlockMatchingConfig, CleanSamples, EdgeRefit, EdgeSnap, FidelityBand, Group, Guidance,
                     GuidedPrior, InitConfig, LayerWeights, OutputHold, Refiner, SidedFill, SingularConfig,
                     SolverConfig, StreamConfig, UpsamplingConfig, ValuePrior)

__all__ = ["RestorerConfig", "TERMS", "from_version1", "load_config_file"]

TERMS = ("nonlocal", "outliers", "singular")
"""The terms of the paper's objective a layer may switch off (TV and the data term are always there):
the nonlocal gradient prior η‖Dx − α‖₁, the sparse outliers γ‖e‖₁ and the singular-pixel test that sets Q."""


@dataclass(frozen=True)
class RestorerConfig:
    """Every setting of :class:`~torch_depth_sr.DepthRestorer`, JSON-serialisable (version 2).

    Top level: ``num_layers``, the ``degradation`` K of guided upsampling (``"area"`` or ``"bicubic"``), the
    ``terms`` of the objective (:data:`TERMS`) and the arithmetic of the networks, ``network_precision``
    (:mod:`torch_depth_sr.precision`: ``"auto"``, ``"float32"`` or ``"bfloat16"``); then one group per part of the
    model. Groups typed ``Optional`` are
    steps that may be off (``None``).

    :meth:`replace` changes top-level fields; a group is given as a group, as a dict of the fields to change, or as
    None (off). Named configurations: :func:`~torch_depth_sr.config.presets.preset_config`.

    Examples:
        >>> c = RestorerConfig().replace(block_matching={"k": 10}, edge_snap=None)
        >>> c.block_matching.k, c.edge_snap, c.solver.iterations(9)
        (10, None, 1)
    """

    VERSION: ClassVar[int] = 2

    num_layers: int = 8
    degradation: str = "area"
    terms: tuple = TERMS
    network_precision: str = "auto"
    weights: LayerWeights = field(default_factory=LayerWeights)
    block_matching: BlockMatchingConfig = field(default_factory=BlockMatchingConfig)
    singular: SingularConfig = field(default_factory=SingularConfig)
    solver: SolverConfig = field(default_factory=SolverConfig)
    initial: InitConfig = field(default_factory=InitConfig)
    upsampling: UpsamplingConfig = field(default_factory=UpsamplingConfig)
    sided_fill: Optional[SidedFill] = field(default_factory=SidedFill)
    value_prior: Optional[ValuePrior] = field(default_factory=ValuePrior)
    clean_samples: Optional[CleanSamples] = field(default_factory=CleanSamples)
    guided_prior: Optional[GuidedPrior] = field(default_factory=GuidedPrior)
    fidelity: Optional[FidelityBand] = field(default_factory=FidelityBand)
    upsample_hold: Optional[OutputHold] = field(default_factory=OutputHold)
    edge_snap: Optional[EdgeSnap] = field(default_factory=EdgeSnap)
    edge_refit: Optional[EdgeRefit] = field(default_factory=EdgeRefit)
    guidance: Optional[Guidance] = None
    refiner: Optional[Refiner] = None
    stream: Optional[StreamConfig] = None

    def __post_init__(self) -> None:
        """Refuse any field outside its domain, naming the field, the value and what is allowed."""
        if isinstance(self.terms, list):
            object.__setattr__(self, "terms", tuple(self.terms))
        integer(1)("num_layers", self.num_layers)
        choice("area", "bicubic")("degradation", self.degradation)
        str_tuple(*TERMS)("terms", self.terms)
        choice(*NETWORK_PRECISIONS)("network_precision", self.network_precision)
        for name, kind in _GROUPS.items():
            v = getattr(self, name)
            if isinstance(v, dict):
                object.__setattr__(self, name, v := kind.from_dict(v, name))
            if v is None and name in _OPTIONAL:
                continue
            if not isinstance(v, kind):
                allowed = f"a {kind.__name__}, a dict of its fields" + (" or None (off)" if name in _OPTIONAL else "")
                raise ParameterError(name, v, allowed)

    def uses(self, term: str) -> bool:
        """Whether the layers compute ``term`` (one of :data:`TERMS`)."""
        return term in self.terms

    def replace(self, **changes: Any) -> "RestorerConfig":
        """A copy with ``changes`` of top-level fields; a group may be given as a dict of the fields to change
        (merged into the current group, or into the group's defaults when it is off) or None (off).

        Examples:
            >>> RestorerConfig().replace(num_layers=4, singular={"rounds": 1}).singular.rounds
            1
        """
        known = {f.name for f in dataclasses.fields(self)}
        unknown = set(changes) - known
        if unknown:
            raise ParameterError("settings", sorted(unknown), f"RestorerConfig fields ({', '.join(sorted(known))})",
                                 "Groups take a dict of their fields, e.g. block_matching={'k': 10}; "
                                 "see docs/config.md.")
        for name, v in list(changes.items()):
            if name in _GROUPS and isinstance(v, dict):
                current = getattr(self, name) or _GROUPS[name]()
                changes[name] = current.replace(**v)
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        """Every setting, nested by group, with ``"version"``: what :meth:`from_dict` reads back."""
        return {"version": self.VERSION, **{f.name: _plain(getattr(self, f.name)) for f in dataclasses.fields(self)}}

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, sort_keys=True)

    @classmethod
    def from_dict(cls, values: dict) -> "RestorerConfig":
        """Build from :meth:`to_dict`'s form (``"version": 2``; fields left out keep their defaults) or from a
        version-1 flat dict (no ``"version"`` or ``"version": 1``), converted with exactly the defaults it had
        (:func:`from_version1`). Every value is checked (ParameterError)."""
        if not isinstance(values, dict):
            raise ParameterError("a RestorerConfig", values, "a dict (a JSON object) of settings")
        version = values.get("version", 1 if set(values) & (FLAT_FIELDS - _TOP_LEVEL) else cls.VERSION)
        if version == 1:
            return from_version1({k: v for k, v in values.items() if k != "version"})
        if version != cls.VERSION:
            raise ParameterError("version", version, f"1 (flat, converted on load) or {cls.VERSION}")
        rest = {k: v for k, v in values.items() if k != "version"}
        known = {f.name for f in dataclasses.fields(cls)}
        if set(rest) - known:
            raise ParameterError("keys", sorted(set(rest) - known), f"RestorerConfig fields ({', '.join(sorted(known))})",
                                 "Remove or rename the unknown keys.")
        return cls(**rest)


_GROUPS: dict = {f.name: t for f, t in zip(dataclasses.fields(RestorerConfig), (
    None, None, None, None, LayerWeights, BlockMatchingConfig, SingularConfig, SolverConfig, InitConfig,
    UpsamplingConfig, SidedFill, ValuePrior, CleanSamples, GuidedPrior, FidelityBand, OutputHold, EdgeSnap, EdgeRefit,
    Guidance, Refiner, StreamConfig)) if t is not None}
_OPTIONAL = {"sided_fill", "value_prior", "clean_samples", "guided_prior", "fidelity", "upsample_hold", "edge_snap",
             "edge_refit", "guidance", "refiner", "stream"}
_TOP_LEVEL = {"num_layers", "degradation"}


def from_version1(values: dict) -> RestorerConfig:
    """The :class:`RestorerConfig` of a version-1 flat dict (some or all of its 80 fields), with exactly the defaults
    a version-1 file had (:func:`~torch_depth_sr.config.version1.version1_settings`).

    Examples:
        >>> from_version1({"snap_rounds": 0, "k": 10}).edge_snap is None
        True
    """
    return RestorerConfig(**version1_settings(values))


def _plain(v: Any) -> Any:
    if isinstance(v, Group):
        return {k: _plain(x) for k, x in dataclasses.asdict(v).items()}
    if isinstance(v, tuple):
        return list(v)
    return v


def load_config_file(path: str | Path) -> RestorerConfig:
    """Read a ``config.json`` written by :meth:`RestorerConfig.to_json` (or by hand, or a version-1 file).

    Raises:
        ModelFileError: the file is missing or unreadable, is not a JSON object (the message gives the line
            and column of invalid JSON), or holds a field out of its domain (the message names the field).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ModelFileError(path, "file not found; a saved model folder holds config.json and state_dict.pt "
                                   "(DepthRestorer.save writes both).") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelFileError(path, f"cannot be read as UTF-8 text ({exc}).") from exc
    try:
        values = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ModelFileError(path, f"invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}.") from exc
    if not isinstance(values, dict):
        raise ModelFileError(path, "must hold a JSON object of RestorerConfig settings, e.g. {\"num_layers\": 8}; "
                                   f"got a JSON {_json_kind(values)}.")
    try:
        return RestorerConfig.from_dict(values)
    except ParameterError as exc:
        raise ModelFileError(path, f"invalid field: {exc}") from exc


def _json_kind(v: Any) -> str:
    if v is None:
        return "null"
    return {bool: "boolean", int: "number", float: "number", str: "string", list: "array"}.get(type(v), "value")
