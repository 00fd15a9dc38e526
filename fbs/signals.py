"""One abort path for every command: SIGINT, SIGTERM and SIGHUP each raise ``KeyboardInterrupt``
(``Signalled``, naming the signal) in the main thread, so whatever is running unwinds through
its own guards (the rig to the safe state and read back, the run file closed "aborted:
interrupted") and the command exits 2, its message naming the signal.

SIGINT is set too, not left as inherited: a command started from a script or as a background
job of a non-interactive shell inherits SIGINT *ignored*, and ``kill -INT`` then did nothing
(a recording grew to 5 GB). A terminal closed under an overnight run sends SIGHUP; a service
manager stops one with SIGTERM. Without a handler both killed the process on the spot: exit
143/129, no safe state, a file left "recording".
"""

from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

from procedures.held_signals import HELD_SIGNALS

#: the signals that abort a command (SIGHUP does not exist on Windows): those a block that
#: must not be cut short holds back (``procedures.held_signals``)
ABORT_SIGNALS = HELD_SIGNALS


class Signalled(KeyboardInterrupt):
    """The ``KeyboardInterrupt`` an abort signal raises; its text is the signal's name
    ("SIGTERM"), so what reports the abort names the signal that came (Python's own Ctrl-C
    is a bare ``KeyboardInterrupt``: no text)."""


def _interrupt(signum: int, frame: FrameType | None) -> None:
    raise Signalled(signal.Signals(signum).name)


@contextmanager
def aborting_on_signals() -> Iterator[None]:
    """Within the block, ``ABORT_SIGNALS`` raise ``KeyboardInterrupt``; the previous handlers
    come back after it. Call from the main thread (the only one Python delivers signals to)."""
    previous = {s: signal.signal(s, _interrupt) for s in ABORT_SIGNALS}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
