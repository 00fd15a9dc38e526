"""Durations as an operator reads them: seconds, minutes, hours."""

from __future__ import annotations


def duration(s: float | None) -> str:
    """``42 s``, ``3.5 min``, ``12 min``, ``1.4 h``; ``?`` when unknown."""
    if s is None:
        return "?"
    if s >= 3600:
        return f"{s / 3600:.1f} h"
    if s >= 600:
        return f"{s / 60:.0f} min"
    if s >= 90:
        return f"{s / 60:.1f} min"
    return f"{s:.0f} s"
