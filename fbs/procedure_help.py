"""``fbs run NAME --help``: the procedure's parameters, each with its type, default, units,
limits and what it is for, as ``--param NAME=VALUE`` takes them.

Everything is read from the procedure itself, so the help cannot drift from the code:

* type and default: the ``Params`` dataclass's fields;
* units: the field name's suffix, the project's naming rule (``hold_s`` seconds,
  ``ramp_rate_urad_per_s`` urad/s, ``delta_pickoff_V`` volts);
* limits: the limits the ``Params`` fields declare (``procedures.paramlimits``: ``1..50``,
  ``> 0``, ``one of X, Y``), the same objects that check the values; the type rules of
  ``procedures.paramtypes`` are stated once, below the list. A limit that ties parameters
  together (a band below the Nyquist frequency) is no one field's: the run states it when a
  value breaks it;
* what it is for: the ``#:`` comment above the field.

Only ``fbs run NAME --help`` imports the procedure; ``fbs --help`` stays fast.
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import re
import textwrap
import types
import typing
from typing import Any

from procedures import paramtypes
from procedures.paramlimits import describe_limits

#: unit words of a field name's suffix, and how they are written
UNITS = {
    "s": "s",
    "ms": "ms",
    "hz": "Hz",
    "v": "V",
    "mv": "mV",
    "deg": "deg",
    "urad": "urad",
    "rad": "rad",
    "db": "dB",
    "nm": "N m",
}


def units(name: str) -> str:
    """The units a field name's suffix states ("" for none): ``kto_urad_per_s_per_V`` urad/s/V."""
    words = name.split("_")
    parts: list[str] = []
    i = len(words)
    # read the suffix backwards: unit (per unit)*
    while i > 0 and words[i - 1].lower() in UNITS:
        parts.insert(0, UNITS[words[i - 1].lower()])
        if i >= 3 and words[i - 2] == "per" and words[i - 3].lower() in UNITS:
            i -= 2
            continue
        i -= 1
        break
    return "/".join(parts) if i < len(words) else ""


def _type_name(hint: Any) -> str:
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_type_name(a) for a in args)
    if origin is list:
        return f"list of {_type_name(args[0])}"
    if origin is dict:
        return f"mapping {_type_name(args[0])} -> {_type_name(args[1])}"
    return {
        int: "integer",
        float: "number",
        str: "text",
        bool: "true/false",
        type(None): "null",
    }.get(hint, str(hint))


def _comments(cls: type) -> dict[str, str]:
    """The ``#:`` comment above each field of ``cls``'s source."""
    try:
        lines = inspect.getsource(cls).splitlines()
    except (OSError, TypeError):
        return {}
    out: dict[str, str] = {}
    pending: list[str] = []
    for line in lines:
        s = line.strip()
        if s.startswith("#:"):
            pending.append(s[2:].strip())
            continue
        m = re.match(r"(\w+)\s*:", s)
        if m and pending:
            out[m.group(1)] = " ".join(pending)
        pending = []
    return out


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return None


def parameter_help(name: str, width: int = 100) -> str:
    """The text ``fbs run NAME --help`` adds: every parameter of procedure ``name``."""
    from procedures.calibrations import get

    proc = get(name)
    cls = proc.Params
    hints = typing.get_type_hints(cls)
    comments = _comments(cls)
    limits = describe_limits(cls)
    lines = textwrap.wrap(
        f"parameters of {proc.name} ({proc.title}), as --param NAME=VALUE (VALUE in JSON):", width
    )
    for f in dataclasses.fields(cls):
        hint = hints.get(f.name, Any)
        facts = [_type_name(hint)]
        u = units(f.name)
        if u:
            facts.append(u)
        if f.name in limits:
            facts.append(f"limits: {limits[f.name]}")
        lines.append(f"  {f.name} = {json.dumps(_default(f))}  ({', '.join(facts)})")
        if f.name in comments:
            lines += textwrap.wrap(
                comments[f.name], width, initial_indent=" " * 6, subsequent_indent=" " * 6
            )
    lines += textwrap.wrap(
        f"Numbers must be finite, durations (names ending in _s) at most {paramtypes.MAX_SECONDS:g} s. "
        "Every value is checked before the rig moves: one of the wrong type, out of its limits or at "
        "odds with another (a band past the Nyquist frequency) is an error (exit 2) naming it and "
        "the limit.",
        width,
    )
    return "\n".join(lines)
