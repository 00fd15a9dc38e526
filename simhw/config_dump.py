"""A sim config back to TOML: the text :func:`simhw.config.load_config` reads.

:func:`dump_config` writes every value of a :class:`~simhw.config.SimConfig` that differs from a
base (default the thesis rig, ``SimConfig()``, which is what ``load_config`` overlays a file on),
in the layout ``from_dict`` reads: a dataclass section is a table (``[site]``), a section keyed
by axis or channel is a table per key (``[gyro.XRD]``, ``[bearing.X]``), a list of dataclasses
is an array of tables (``[[pickup]]``, written whole, as ``from_dict`` replaces the list), and a
list value such as ``pickoff_lines`` is a TOML array (written whole). Floats are written with
``repr`` precision, so ``from_dict(tomllib.loads(dump_config(cfg))) == cfg``.

Nothing here names a field: the sections and keys come from the dataclasses themselves
(``dataclasses.asdict``), so a field added to ``simhw.config`` is written without an edit here.
The standard library reads TOML (``tomllib``) but does not write it; this module is the writer.
"""

from __future__ import annotations

import math
import numbers
import re
from typing import Any

from simhw.config import SimConfig, to_dict

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")
#: TOML basic strings must escape these (tab may stay, but escaping it is as valid)
_ESCAPES = {
    '"': '\\"',
    "\\": "\\\\",
    "\b": "\\b",
    "\t": "\\t",
    "\n": "\\n",
    "\f": "\\f",
    "\r": "\\r",
}


def dump_config(cfg: SimConfig, base: SimConfig | None = None, header: str = "") -> str:
    """The TOML text of every value of ``cfg`` that differs from ``base`` (default the thesis
    rig); ``from_dict(tomllib.loads(text), base=base)`` gives ``cfg`` back. ``header``'s lines
    become ``#`` comments at the top of the file.

    A key ``cfg`` lacks but ``base`` has (an entry removed from a keyed section) cannot be
    written as an overlay and raises ``ValueError``; a value TOML has no form for (``None``, an
    arbitrary object) raises ``TypeError``, both naming the dotted key."""
    cur = to_dict(cfg)
    ref = to_dict(base if base is not None else SimConfig())
    lines = [("# " + _comment(line)).rstrip() for line in header.splitlines()]
    body: list[str] = []
    _table(body, (), cur, ref)
    if lines and body:
        lines.append("")
    return "\n".join(lines + body) + ("\n" if lines or body else "")


class _Missing:
    """A key the base config does not have."""


_MISSING = _Missing()


def _same(a: Any, b: Any) -> bool:
    """Equal as the dataclasses compare them (a tuple equals the list of its items)."""
    if isinstance(a, _Missing) or isinstance(b, _Missing):
        return False
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    try:
        return bool(a == b)
    except ValueError:  # an array: equal only item by item
        tolist = getattr(a, "tolist", None)
        return callable(tolist) and _same(tolist(), b.tolist() if hasattr(b, "tolist") else b)


def _is_table_array(value: Any) -> bool:
    return (
        isinstance(value, (list, tuple))
        and len(value) > 0
        and all(isinstance(v, dict) for v in value)
    )


def _table(
    out: list[str], path: tuple[str, ...], cur: dict[str, Any], ref: dict[str, Any] | None
) -> None:
    """Write the keys of ``cur`` that differ from ``ref`` (all of them when ``ref`` is None) as
    the table at ``path``: its plain keys under its header, then its sub-tables and arrays of
    tables (TOML wants a table's own keys before any sub-table's header)."""
    if ref is not None:
        gone = [k for k in ref if k not in cur]
        if gone:
            raise ValueError(
                f"sim config: '{_dotted((*path, gone[0]))}' is in the base config but not in "
                "this one; an overlay cannot remove a key"
            )
    plain: list[str] = []
    subtables: list[tuple[str, dict[str, Any], dict[str, Any] | None]] = []
    arrays: list[tuple[str, list[Any]]] = []
    for key, value in cur.items():
        old = _MISSING if ref is None else ref.get(key, _MISSING)
        if isinstance(value, dict):
            subtables.append((key, value, old if isinstance(old, dict) else None))
            continue
        if ref is not None and _same(value, old):
            continue
        if _is_table_array(value):
            arrays.append((key, list(value)))
        else:
            plain.append(f"{_key(key)} = {_value(value, (*path, key))}")
    if plain:
        if path:
            if out:
                out.append("")
            out.append(f"[{_dotted(path)}]")
        out.extend(plain)
    for key, value, old_table in subtables:
        _table(out, (*path, key), value, old_table)
    for key, items in arrays:
        for i, item in enumerate(items):
            if out:
                out.append("")
            out.append(f"[[{_dotted((*path, key))}]]")
            for k, v in item.items():
                out.append(f"{_key(k)} = {_value(v, (*path, f'{key}[{i}]', k))}")


def _comment(text: str) -> str:
    """A comment line holds no control character but tab (TOML): others are shown escaped."""
    return "".join(
        c if c == "\t" or not (ord(c) < 0x20 or ord(c) == 0x7F) else f"\\x{ord(c):02x}"
        for c in text
    )


def _dotted(path: tuple[str, ...]) -> str:
    return ".".join(_key(p) for p in path)


def _key(key: str) -> str:
    return key if _BARE_KEY.match(key) else _string(key)


def _string(s: str) -> str:
    def esc(c: str) -> str:
        if c in _ESCAPES:
            return _ESCAPES[c]
        if ord(c) < 0x20 or ord(c) == 0x7F:
            return f"\\u{ord(c):04x}"
        return c

    return '"' + "".join(esc(c) for c in s) + '"'


def _value(v: Any, path: tuple[str, ...]) -> str:
    """One TOML value: bool, integer, float (repr: shortest text that reads back exactly),
    string, array (nested as needed) or inline table. numpy scalars are numbers too."""
    if isinstance(v, bool) or type(v).__name__ == "bool_":
        return "true" if bool(v) else "false"
    if isinstance(v, numbers.Integral):
        return str(int(v))
    if isinstance(v, numbers.Real):
        x = float(v)
        if math.isnan(x):
            return "nan"
        if math.isinf(x):
            return "inf" if x > 0 else "-inf"
        return repr(x)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x, path) for x in v) + "]"
    if isinstance(v, dict):
        return (
            "{"
            + ", ".join(f"{_key(str(k))} = {_value(x, (*path, str(k)))}" for k, x in v.items())
            + "}"
        )
    tolist = getattr(v, "tolist", None)  # a numpy array
    if callable(tolist):
        return _value(tolist(), path)
    raise TypeError(f"sim config: '{'.'.join(path)}' = {v!r} has no TOML form")


__all__ = ["dump_config"]
