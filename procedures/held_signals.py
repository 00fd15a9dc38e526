"""Abort signals held back over a block that must not be cut short, and acted on after it.

A summary written whole, a result line and the curves' view of it updated together: within
``signals_held()`` the handlers of SIGINT, SIGTERM and SIGHUP only note the signal; after the
block the first one noted goes to the handler that was there before (``fbs.signals``'s raises
``KeyboardInterrupt``). Only the main thread runs Python's handlers, so only there can they be
held: elsewhere the block just runs.

Blocking the signals with ``pthread_sigmask`` does not hold them: the mask is the calling
thread's, and the kernel hands a process-directed signal to any thread that does not block it
(a process pool's manager thread, a CAN notifier). Its C handler then trips Python's flag, and
the main thread runs the Python handler at its next instruction - inside the block. An
interrupted ``fbs campaign`` lost a run that way: its line was in ``runs.jsonl``, its curves
did not count it.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["HELD_SIGNALS", "signals_held"]

#: the signals held (SIGHUP does not exist on Windows)
HELD_SIGNALS = tuple(
    getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n)
)


@contextmanager
def signals_held() -> Iterator[None]:
    """Run the block with ``HELD_SIGNALS`` noted, not acted on; then act on the first one noted
    as the handler before the block would have (module docstring)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = {
        s: signal.signal(s, lambda signum, frame: caught.append(signum)) for s in HELD_SIGNALS
    }
    try:
        yield
    finally:
        for s, handler in previous.items():
            if handler is not None:  # None: not set from Python, nothing to put back
                signal.signal(s, handler)
        if caught:
            handler = previous[caught[0]]
            if callable(handler):
                handler(caught[0], None)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(caught[0])
