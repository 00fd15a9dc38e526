"""Clocks for the simulated rig (DESIGN.md section 2: time belongs to the rig).

``VirtualClock`` lets the simulation run as fast as it can; ``PacedClock`` holds it back so
simulated time never runs ahead of wall time (the live console's default, ``sim?realtime=1``).
Both report the rig's time; neither is consulted by the physics, so a run gives the same
samples under either clock.
"""

from __future__ import annotations

import time


class VirtualClock:
    """Simulated time advances only when the simulation steps."""

    paced = False

    def __init__(self) -> None:
        self.now = 0.0

    def advance_to(self, t: float) -> None:
        self.now = t

    def unix_time(self, t: float) -> float | None:
        """Wall-clock time of simulated time ``t``: none, time here is not the wall's."""
        return None


class PacedClock(VirtualClock):
    """Simulated time advances no faster than wall time (scaled by ``speed``)."""

    paced = True

    def __init__(self, speed: float = 1.0) -> None:
        super().__init__()
        if speed <= 0:
            raise ValueError(f"clock speed {speed} must be > 0")
        self.speed = speed
        self._t0 = time.monotonic()
        self._unix0 = time.time()

    def unix_time(self, t: float) -> float:
        """The earliest wall-clock (Unix) time at which simulated time ``t`` is reached."""
        return self._unix0 + t / self.speed

    def advance_to(self, t: float) -> None:
        delay = self._t0 + t / self.speed - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        self.now = t
