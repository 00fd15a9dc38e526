"""Standalone checks of a procedure's parameters against their declared types, before the
``Params`` dataclass (and its own range checks) ever sees them.

``--param`` values arrive as JSON, so ``repetitions=1.5``, ``repetitions=true``,
``hold_s=Infinity`` or ``kg_tolerance=NaN`` parse without complaint; a dataclass does not check
its annotations, and such values used to fail deep inside a run (a ``TypeError`` after the rig
had moved) or pass silently (``true`` taken as 1). ``check`` refuses them with the parameter,
the value and the rule, for every procedure alike, from the annotations alone:

* ``int``: an integer (not a bool, not 1.5);
* ``float``: a finite number (not a bool, not NaN or infinity); a duration (a name ending in
  ``_s``) at most ``MAX_SECONDS``, and 0 or at least ``MIN_SECONDS``; a frequency (``_hz``) 0 or at least ``MIN_HZ``;
* ``str``, ``bool``: that type;
* ``list[T]``, ``dict[str, T]``: each element by the rule for ``T``;
* ``X | None``: ``None`` or the rule for ``X``.

Limits that belong to one procedure (``repetitions`` 1..50, ``axis`` X or Y) are declared on its
``Params`` fields and checked on construction (``procedures.paramlimits``); this module reads
the bare types (``typing.get_type_hints`` drops the ``Annotated`` limits).
"""

from __future__ import annotations

import math
import types
import typing
from collections.abc import Mapping
from typing import Any

#: the longest duration any parameter may ask for (a year): beyond it a typo, not a plan
MAX_SECONDS = 3.2e7
#: the shortest non-zero duration (a millisecond) and frequency (11 days a cycle) a parameter
#: may ask for: below them a slip (1e-320 is a denormal, whose reciprocal overflows), not a plan
MIN_SECONDS = 1e-3
MIN_HZ = 1e-6


class ParamTypeError(ValueError):
    """A parameter's value is not of its declared type; the message names both."""


def check(params_cls: type, data: Mapping[str, Any], procedure: str) -> None:
    """Raise ``ParamTypeError`` for the first value in ``data`` that does not fit the type
    ``params_cls`` (a dataclass) declares for it. Unknown names are left to the caller."""
    hints = typing.get_type_hints(params_cls)
    for name, value in data.items():
        if name in hints:
            why = _mismatch(hints[name], value, name)
            if why:
                raise ParamTypeError(f"{procedure}: parameter {name} = {value!r}: {why}")


def _mismatch(hint: Any, value: Any, name: str) -> str:
    """Why ``value`` does not fit ``hint`` ("" when it does)."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return ""
        rest = [a for a in args if a is not type(None)]
        whys = [_mismatch(a, value, name) for a in rest]
        return "" if "" in whys else whys[0]
    if origin is list:
        if not isinstance(value, list):
            return "must be a list"
        for i, v in enumerate(value):
            why = _mismatch(args[0], v, name)
            if why:
                return f"element {i} ({v!r}) {why}"
        return ""
    if origin is dict:
        if not isinstance(value, dict):
            return 'must be a mapping, e.g. {"X": 1.0}'
        for k, v in value.items():
            why = _mismatch(args[1], v, name)
            if why:
                return f"entry {k!r} ({v!r}) {why}"
        return ""
    if hint is bool:
        return "" if isinstance(value, bool) else "must be true or false"
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            return "must be an integer"
        return ""
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return "must be a number"
        if not math.isfinite(value):
            return "must be a finite number"
        if name.endswith("_s") and abs(value) > MAX_SECONDS:
            return f"is beyond the longest duration a parameter may ask for ({MAX_SECONDS:g} s, a year)"
        if name.endswith("_s") and 0 < abs(value) < MIN_SECONDS:
            return f"must be 0 or at least {MIN_SECONDS:g} s (a millisecond) in size"
        if name.endswith("_hz") and 0 < abs(value) < MIN_HZ:
            return f"must be 0 or at least {MIN_HZ:g} Hz in size"
        return ""
    if hint is str:
        return "" if isinstance(value, str) else "must be a string"
    return ""
