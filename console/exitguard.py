"""The console leaves when its terminal goes, without the screen's help.

When the console's tmux session or SSH connection goes, the console gets SIGHUP (or the
operator's SIGTERM), and its terminal is gone: a write to it can block for ever (Textual's
writer thread stops, and the app's main thread then waits on its bounded queue). So leaving
must not depend on the screen. ``ExitGuard``:

* takes SIGHUP and SIGTERM with plain signal handlers (they run in the main thread even while
  it waits on a lock) and watches the terminal for a hang-up (``poll`` on its fd: POLLHUP,
  POLLERR, POLLNVAL), on a thread of its own;
* on either, asks the rig thread to stop (a running procedure aborted, a recording closed
  "aborted: <why>", the rig safe and read back) and the app to quit, and gives that
  ``grace_s``; if the process is still there then (the screen stuck), it finishes the rig
  thread's shutdown itself and ends the process with exit code 2 (``os._exit``: nothing may
  wait on the dead terminal).

A signal ends ``fbs console`` with exit code 2 either way: the session did not end by the
operator's quit.
"""

from __future__ import annotations

import logging
import os
import select
import signal
import sys
import threading
from collections.abc import Callable

log = logging.getLogger(__name__)

#: how long the app has to quit by itself after a signal or a hang-up, s
GRACE_S = 5.0
#: how long the forced path waits for the rig thread (its recording closed, the rig safe), s
RIG_S = 20.0
EXIT_SIGNALLED = 2


class ExitGuard:
    """``stopping(why)`` asks the rig thread and the app to stop (non-blocking); ``finish(why,
    timeout_s) -> bool`` waits for the rig thread's shutdown."""

    def __init__(
        self,
        stopping: Callable[[str], None],
        finish: Callable[[str, float], bool],
        *,
        tty_fd: int | None = None,
        grace_s: float = GRACE_S,
        poll_s: float = 0.25,
    ) -> None:
        self._stopping, self._finish = stopping, finish
        self.tty_fd = tty_fd if tty_fd is not None else _terminal_fd()
        self.grace_s, self.poll_s = grace_s, poll_s
        self.tripped: str | None = None
        self._done = threading.Event()
        self._lock = threading.Lock()
        self._saved: dict[int, object] = {}

    def install(self) -> ExitGuard:
        """Signal handlers (call from the main thread) and the terminal watch."""
        for sig in (signal.SIGHUP, signal.SIGTERM):
            self._saved[sig] = signal.signal(sig, self._on_signal)
        if self.tty_fd is not None:
            threading.Thread(target=self._watch, name="console-terminal-watch", daemon=True).start()
        return self

    def done(self) -> None:
        """The console ended by itself: stand down, restore the signal handlers."""
        self._done.set()
        for sig, handler in self._saved.items():
            signal.signal(sig, handler)  # type: ignore[arg-type]
        self._saved.clear()

    def _on_signal(self, sig: int, frame: object) -> None:
        self.trip(f"the console got {signal.Signals(sig).name}")

    def _watch(self) -> None:
        poller = select.poll()
        assert self.tty_fd is not None
        poller.register(self.tty_fd, select.POLLHUP | select.POLLERR | select.POLLNVAL)
        while not self._done.is_set():
            if poller.poll(self.poll_s * 1000):
                self.trip("the console's terminal went away")
                return

    def trip(self, why: str) -> None:
        """Stop for ``why``: at most once; never blocks the caller (a signal handler)."""
        with self._lock:
            if self.tripped is not None or self._done.is_set():
                return
            self.tripped = why
        threading.Thread(
            target=self._leave, args=(why,), name="console-exit-guard", daemon=True
        ).start()

    def _leave(self, why: str) -> None:
        log.warning("%s: aborting what runs, closing files, leaving the rig safe, exiting", why)
        self._stopping(why)
        if self._done.wait(self.grace_s):
            return  # the app quit by itself
        log.error(
            "%s: the console did not quit within %g s (its screen stuck): exiting without it",
            why,
            self.grace_s,
        )
        finished = self._finish(why, RIG_S)
        log.log(
            logging.INFO if finished else logging.ERROR,
            "rig thread %s; exit code %d",
            "finished" if finished else "did NOT finish",
            EXIT_SIGNALLED,
        )
        logging.shutdown()
        os._exit(EXIT_SIGNALLED)


def _terminal_fd() -> int | None:
    """The console's terminal (stdin's, if a tty), to watch for a hang-up."""
    try:
        fd = sys.__stdin__.fileno() if sys.__stdin__ is not None else -1
    except (OSError, ValueError):
        return None
    return fd if fd >= 0 and os.isatty(fd) else None
