"""Deadlines that leave out the time this process could not run.

A deadline on the wall clock measures the host as much as the device. On a loaded machine a
process can go seconds without running: descheduled among other busy processes, a C call
holding the GIL (an HDF5 flush to a slow disk), a paused VM. A real rig's devices run on
their own meanwhile, so a real rig's drivers keep the wall clock (``time.monotonic``). The
simulated rig's devices run in this very process: every such pause stops them too, and a
wall-clock deadline then trips on the host's load, not on the rig (issue 19 point 10:
"ADC stalled: no data for 3 s", "node silent: no heartbeat for 5.5 s" in a `make test` with
both cores kept busy).

``RunningClock`` is a monotonic clock in seconds that the process could run: a thread ticks
every ``TICK_S``; an interval between two ticks longer than ``TICK_S + SLACK_S`` was a pause of
the process (the ticker is a Python thread, so it is held up by whatever holds up the others),
and its excess is left out. A device that is really silent while the process runs freely
still times out on schedule. The drivers take it as their ``monotonic`` argument; the sim rig
passes one (``simhw.rig_scheme``), a serial rig passes none.
"""

from __future__ import annotations

import threading
import time


class RunningClock:
    """``clock()``: monotonic seconds, less the pauses of this process (module docstring)."""

    #: the ticker's period, s
    TICK_S = 0.02
    #: lateness of a tick that is still scheduling jitter, not a pause, s
    SLACK_S = 0.1

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._last = time.monotonic()
        self._excluded = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="running-clock", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self.TICK_S):
            now = time.monotonic()
            with self._lock:
                late = now - self._last - self.TICK_S
                if late > self.SLACK_S:
                    self._excluded += late - self.SLACK_S
                self._last = now

    @property
    def excluded_s(self) -> float:
        """Seconds left out so far."""
        with self._lock:
            return self._excluded

    def __call__(self) -> float:
        now = time.monotonic()
        with self._lock:
            # a pause still under way (the ticker has not run since): left out already, so the
            # value never goes back when the ticker books it
            pending = max(0.0, now - self._last - self.TICK_S - self.SLACK_S)
            return now - self._excluded - pending

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)
