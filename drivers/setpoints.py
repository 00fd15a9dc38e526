"""Checks every set-point passes before a byte leaves the host."""

from __future__ import annotations

import math
from collections.abc import Iterable

from drivers.errors import SetpointRangeError


def check_name(what: str, name: object, allowed: Iterable[str]) -> str:
    allowed = tuple(allowed)
    if name not in allowed:
        raise SetpointRangeError(f"{what} {name!r} does not exist (choose one of {', '.join(allowed)}); nothing was sent",
                                 value=name, limit=allowed)
    return name  # type: ignore[return-value]


def check_value(what: str, value: object, limit: float, why: str, lo: float | None = None) -> float:
    """``value`` as a float within ``[lo, limit]`` (``lo`` defaults to ``-limit``), else SetpointRangeError."""
    lo = -limit if lo is None else lo
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise SetpointRangeError(f"{what} {value!r} is not a number; nothing was sent", value=value) from None
    if not math.isfinite(v) or not lo <= v <= limit:
        span = f"+-{limit:g}" if lo == -limit else f"{lo:g}..{limit:g}"
        raise SetpointRangeError(f"{what} {value!r} is outside {span} ({why}); nothing was sent",
                                 value=value, limit=limit)
    return v
