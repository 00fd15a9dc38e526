"""Waiting in the driver tests for what threads and other processes do: polled under a hang
guard, never a deadline (a node, a notifier or a served rig is late on a loaded box)."""

from __future__ import annotations

import time
from collections.abc import Callable


def wait_for(holds: Callable[[], object], what: str, guard_s: float = 60.0) -> None:
    """Return once ``holds()`` is true; AssertionError naming ``what`` after ``guard_s``."""
    t_end = time.monotonic() + guard_s
    while not holds():
        if time.monotonic() > t_end:
            raise AssertionError(f"{what}: not seen within {guard_s:g} s (hung?)")
        time.sleep(0.01)
