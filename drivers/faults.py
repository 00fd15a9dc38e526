"""One latch per rig for faults that happen off the caller's thread.

A reader or heartbeat thread that sees a device fault ``report``s it here. The first fault
is kept, the listeners run once (the rig goes safe), and every later driver call
``check``s the latch and raises the fault, so nothing is lost in a background thread.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from drivers.errors import DriverError

log = logging.getLogger(__name__)


class FaultLatch:
    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._fault: DriverError | None = None
        self._listeners: list[Callable[[DriverError], None]] = []

    @property
    def fault(self) -> DriverError | None:
        return self._fault

    def on_fault(self, listener: Callable[[DriverError], None]) -> None:
        self._listeners.append(listener)

    def report(self, fault: DriverError) -> None:
        with self._lock:
            if self._fault is not None:
                log.info("further fault while latched: %s", fault)
                return
            self._fault = fault
        log.error("rig fault: %s", fault)
        for listener in self._listeners:
            try:
                listener(fault)
            except Exception:  # a listener must not hide the fault
                log.exception("fault listener failed")

    def check(self) -> None:
        if self._fault is not None:
            raise self._fault

    def clear(self) -> DriverError | None:
        with self._lock:
            fault, self._fault = self._fault, None
        return fault
