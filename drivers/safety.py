"""Safety on abort: the one piece of code that drives the rig safe when a run does not end cleanly.

Teardown belongs to whoever executes (OpenHTF's executor, bluesky's ``finalize_wrapper``), not
to a data writer. Every path that commands the rig - the procedure runner, ``fbs record``
(``daq.recorder.record``) and the console's rig thread - wraps its commands in
``SafeOnAbort``; on any exit that is not clean (an exception, Ctrl-C, a SIGTERM or SIGHUP
turned into an exception, a full disk, a device fault) it drives the rig to the safe state
(mode 1, every torquer bias and command input zero, caging released: ``Rig.safe``, which reads
each back from the nodes), logs what was and was not confirmed, and lets the exception go on.
The recorder only records and closes its file with its status.

The guard is entered twice around a recording, and each exception is handled once::

    guard = SafeOnAbort(rig, "earth-rate")
    with guard, Acquisition(rig, path, ...) as acq, guard:
        ...                  # commands and samples

The inner entry runs first on an abort, while the file is still open, so the rig's ``safe``
event lands in the file before it is closed "aborted: <why>"; the outer entry catches what
only closing the file can raise (a full disk at the last flush) and passes over the exception
the inner one already handled. A clean exit changes nothing: a procedure that ends normally
leaves the rig as its last step left it.

Device faults seen off the caller's thread are the rig's own business: the fault latch drives
the rig safe at once (``Rig._on_fault``), and every later call raises the fault, which then
reaches this guard like any other exception.
"""

from __future__ import annotations

import logging
from types import TracebackType

from drivers.rig import Rig, SafeReport

log = logging.getLogger(__name__)


def describe(exc: BaseException) -> str:
    """Why a run stopped, in words: the exception's type and message ("interrupted" for Ctrl-C)."""
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted"
    return f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__


def go_safe(rig: Rig, why: str) -> SafeReport:
    """Drive ``rig`` to the safe state now, read it back, and log the outcome; never raises for
    a device that does not answer (the report says what was not confirmed)."""
    log.warning("%s: putting the rig in the safe state", why)
    try:
        report = rig.safe()
    except (
        Exception
    ) as exc:  # the rig itself is gone: say so; the nodes' watchdogs are the last line
        report = SafeReport(failed=[f"safe state not commanded: {type(exc).__name__}: {exc}"])
    if not report.ok:
        log.error("the rig did not confirm the safe state: %s", "; ".join(report.failed))
    return report


class SafeOnAbort:
    """Context manager: on an exit that is not clean, ``go_safe`` once per exception, then re-raise."""

    def __init__(self, rig: Rig, what: str = "run") -> None:
        self.rig = rig
        self.what = what
        #: what the last abort achieved (None until one happened)
        self.report: SafeReport | None = None
        self._handled: BaseException | None = None

    def __enter__(self) -> SafeOnAbort:
        return self

    def __exit__(
        self, et: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if exc is not None:
            self.abort(exc)

    def abort(self, exc: BaseException) -> SafeReport | None:
        """Drive the rig safe for ``exc`` unless that exception was already handled; for code
        that holds a run open across calls (the console) and so cannot use a ``with`` block."""
        if exc is self._handled:
            return self.report
        self._handled = exc
        self.report = go_safe(self.rig, f"{self.what} aborted ({describe(exc)})")
        return self.report
