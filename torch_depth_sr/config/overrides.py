"""Changes to a configuration given as one dict (the JSON flags of the command-line tools: ``--config``,
``--model``, ``--base``, ``--trials``, ``--configs``, ``--start``): :func:`apply_overrides`."""
from __future__ import annotations

import copy
import dataclasses
from typing import Any, Optional

from ..errors import ParameterError
from .restorer import RestorerConfig, from_version1
from .version1 import _SETS, FLAT_FIELDS, to_version1

__all__ = ["apply_overrides"]

_V2 = frozenset(f.name for f in dataclasses.fields(RestorerConfig))


def apply_overrides(config: RestorerConfig, overrides: Optional[dict]) -> RestorerConfig:
    """``config`` with the changes of one dict, in any of three forms:

    * version 2, as :meth:`RestorerConfig.replace` takes them: top-level fields, a group as a dict of the fields
      to change (merged) or None (off): ``{"block_matching": {"k": 10}, "edge_snap": None}``;
    * version 2 with dotted paths: ``{"block_matching.k": 10, "upsampling.jbu.radius": 3}`` (may be mixed with
      the form above);
    * version 1, the flat field names of the files written before 2026-12-03: ``{"k": 10, "snap_rounds": 0}``,
      each changing the group it belonged to as version 1 would have, sentinels included
      (:func:`flat_changes`); groups not named keep ``config``'s settings.

    ``"version": 1`` or ``2`` in the dict says which; without it the keys decide (``num_layers`` and
    ``degradation`` are in both; ``guided_prior`` is version 1 when its value is a number). A dict mixing
    version-1 and version-2 names is refused, as are unknown names (ParameterError).

    Examples:
        >>> c = apply_overrides(RestorerConfig(), {"k": 10, "snap_rounds": 0})
        >>> c.block_matching.k, c.edge_snap
        (10, None)
        >>> apply_overrides(RestorerConfig(), {"block_matching.k": 10, "edge_snap": None}) == c
        True
    """
    if not overrides:
        return config
    if not isinstance(overrides, dict):
        raise ParameterError("overrides", overrides, "a dict (a JSON object) of RestorerConfig settings")
    values = copy.deepcopy(overrides)
    version = values.pop("version", None)
    if version not in (None, 1, 2):
        raise ParameterError("version", version, "1 (flat field names) or 2 (groups)")
    if version is None:
        kinds = {k: _kind(k, v) for k, v in values.items()}
        unknown = sorted(k for k, kind in kinds.items() if kind is None)
        if unknown:
            raise ParameterError("keys", unknown, f"RestorerConfig fields ({', '.join(sorted(_V2))}), dotted paths "
                                 "of their groups' fields (block_matching.k), or version-1 flat names (k)",
                                 "See docs/config.md.")
        v1 = sorted(k for k, kind in kinds.items() if kind == "v1")
        v2 = sorted(k for k, kind in kinds.items() if kind == "v2")
        if v1 and v2:
            raise ParameterError("keys", sorted(values), "either version-2 names or version-1 flat names, not both",
                                 f"Version 1: {v1}; version 2: {v2}.")
        version = 1 if v1 else 2
    if version == 1:
        return config.replace(**flat_changes(values, config))
    return config.replace(**_nested(values))


def _kind(key: str, value: Any) -> Optional[str]:
    """``"v1"``, ``"v2"``, ``"both"`` (the same field in both versions) or None (unknown) for one key."""
    if key in FLAT_FIELDS and key in _V2:
        if key == "guided_prior":  # a number in version 1, a group (dict) or None in version 2
            return "v1" if isinstance(value, (int, float)) and not isinstance(value, bool) else "v2"
        return "both"
    if key in FLAT_FIELDS:
        return "v1"
    if key in _V2 or key.split(".")[0] in _V2:
        return "v2"
    return None


def _nested(values: dict) -> dict:
    """Dotted paths (``"block_matching.k"``) as nested dicts, merged with the groups given as dicts."""
    out: dict = {k: v for k, v in values.items() if "." not in k}
    for key, v in values.items():
        if "." not in key:
            continue
        *path, last = key.split(".")
        node = out
        for i, part in enumerate(path):
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ParameterError(".".join(path[:i + 1]), node, "a dict of fields to change when "
                                     f"{key!r} is given too", "Give the group either whole or by dotted paths.")
        node[last] = v
    return out


def flat_changes(values: dict, base: Optional[RestorerConfig] = None) -> dict:
    """The version-2 changes (:meth:`RestorerConfig.replace <torch_depth_sr.config.RestorerConfig.replace>`
    arguments) that a partial version-1 flat dict makes to ``base`` (default: the defaults).

    Each version-1 field changes the group(s) it belonged to as version 1 would have: the group is read back to its
    version-1 fields, the given ones replace them, and the group is converted again, so sentinels switch a step
    off (``snap_rounds=0`` -> ``edge_snap=None``), a sentinel's opposite on again (merged into the group's
    defaults), and a setting of a group that is off leaves it off. Groups the dict does not touch keep ``base``'s
    settings exactly. A group that stays on comes back as a dict of the fields that change.

    Examples:
        >>> flat_changes({"k": 10, "snap_rounds": 0})
        {'block_matching': {'k': 10}, 'edge_snap': None}
    """
    if not isinstance(values, dict):
        raise ParameterError("version-1 settings", values, "a dict of version-1 RestorerConfig fields")
    unknown = set(values) - FLAT_FIELDS
    if unknown:
        raise ParameterError("keys", sorted(unknown),
                             f"version-1 RestorerConfig fields ({', '.join(sorted(FLAT_FIELDS))})",
                             "Remove or rename the unknown keys.")
    base = RestorerConfig() if base is None else base
    new = from_version1({**to_version1(base), **values})
    changes: dict = {}
    for key in values:
        for name in _SETS[key]:
            old, now = getattr(base, name), getattr(new, name)
            if name in changes or old == now:
                continue
            if now is None or not hasattr(now, "to_dict"):  # off, or a top-level value
                changes[name] = now
            else:  # merged into the current group, or into the group's defaults when it was off
                changes[name] = _differences(type(now)() if old is None else old, now)
    return changes


def _differences(old, new) -> dict:
    """The fields of group ``new`` that differ from group ``old`` (nested groups as dicts of theirs)."""
    out = {}
    for k, x in new.to_dict().items():
        was, now = getattr(old, k), getattr(new, k)
        if was != now:
            out[k] = _differences(was, now) if hasattr(now, "to_dict") else now
    return out
