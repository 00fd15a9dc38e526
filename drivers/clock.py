"""The rig's clock (DESIGN.md section 2: time belongs to the rig).

Procedures wait and timestamp with ``rig.clock``, never ``time.sleep``: on hardware it is
the wall clock; on the simulated rig (``simhw.rig_server.SimClock``) it is simulated time,
which in virtual mode advances only as far as someone waits or asks for data.
"""

from __future__ import annotations

import time
from typing import Protocol


class RigClock(Protocol):
    #: True when time advances on demand (simulation), not by itself.
    virtual: bool

    def now(self) -> float:
        """Seconds of rig time since the rig was opened (or the simulation started)."""

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` of rig time."""

    def demand(self, t: float) -> None:
        """Someone will wait for data up to rig time ``t``: a virtual clock runs to it."""

    def horizon(self) -> float:
        """The rig time a command sent now acts at: ``now()``, but on a virtual clock the
        time someone demanded or a command was scheduled for (``at``), which the rig runs to."""

    def at(self, t: float) -> None:
        """The next command is for rig time ``t``: wait until then (hardware, a paced
        simulation); a virtual clock does not wait, and a command sent next acts at ``t``.
        A stream of set-points paced this way is timed by the rig, not by the host's reads."""

    def unix_time(self, t: float) -> float | None:
        """Wall-clock (Unix) time of rig time ``t``; None for a virtual clock. On a paced
        simulation it is the earliest time ``t`` can be reached (the rig may lag)."""


class WallClock:
    """Real hardware: monotonic wall time from when the rig was opened."""

    virtual = False

    def __init__(self) -> None:
        self._t0 = time.monotonic()

    def now(self) -> float:
        return time.monotonic() - self._t0

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)

    def demand(self, t: float) -> None:
        pass

    def horizon(self) -> float:
        return self.now()

    def at(self, t: float) -> None:
        self.sleep(t - self.now())

    def unix_time(self, t: float) -> float:
        return time.time() - (self.now() - t)
