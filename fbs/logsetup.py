"""Logging for the ``fbs`` commands: timestamped lines on stderr, a live status line on a
terminal, and ``-v`` for this project's loggers only.

Records of this project's packages are shown from INFO, or DEBUG with ``-v``; every other
library's (matplotlib's font manager logs 70 lines at DEBUG, canopen each SDO transfer at INFO)
only from WARNING, so ``-v`` says what the rig and the procedure do: the rule and the line
format (timestamps with their UTC offset) are ``drivers.logrule``'s, the console's too.
Python's warnings become log records (``py.warnings``): they are timestamped, land in a run's
log, and do not break the status line.

Two attributes a record may carry (``extra=``) steer it:

* ``stderr=False``: for the run's log file only (``procedures.runlog``), e.g. its header line;
* ``progress=True``: progress text that the live status line shows on a terminal, so it is not
  printed there again; on a pipe or file it is printed as a plain line.
"""

from __future__ import annotations

import logging
import os
import shutil
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TextIO

from drivers.logrule import Formatter, ProjectFilter, set_levels

#: erase from the cursor to the end of the line (ANSI/VT100 "EL")
_ERASE_LINE = "\x1b[K"


def formatter() -> logging.Formatter:
    return Formatter()


class StderrHandler(logging.Handler):
    """Each record as one timestamped line on the process's *current* ``sys.stderr`` (looked up
    at each record, so redirection after setup is followed), and, on a terminal, one status line
    kept below them: a record erases it, is written, and the status line is drawn again."""

    def __init__(self) -> None:
        super().__init__()
        self.setFormatter(formatter())
        self.addFilter(ProjectFilter())
        self.addFilter(self._shown)
        self._status = ""

    @property
    def stream(self) -> TextIO:
        return sys.stderr

    def is_terminal(self) -> bool:
        """stderr is a terminal that understands carriage return and "erase line"."""
        try:
            return self.stream.isatty() and os.environ.get("TERM") != "dumb"
        except (AttributeError, ValueError):  # no stream, or a closed one
            return False

    def _shown(self, record: logging.LogRecord) -> bool:
        if getattr(record, "stderr", True) is False:
            return False
        return not (getattr(record, "progress", False) and self.is_terminal())

    def _columns(self) -> int:
        try:
            columns = os.get_terminal_size(self.stream.fileno()).columns
        except (AttributeError, ValueError, OSError):
            columns = 0
        # a terminal that reports no size (a new pty): $COLUMNS, else 80
        return columns if columns > 0 else shutil.get_terminal_size().columns

    def _write(self, text: str) -> None:
        stream = self.stream
        enc = getattr(stream, "encoding", None) or "utf-8"
        # a character the stream cannot encode (a file's odd channel name) is escaped, not a
        # logging error with a traceback in the middle of the output
        stream.write(text.encode(enc, "backslashreplace").decode(enc))
        stream.flush()

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = self.format(record) + "\n"
            if self._status:
                text = "\r" + _ERASE_LINE + text + self._status_text()
            self._write(text)
        except RecursionError:
            raise
        except Exception:
            self.handleError(record)

    def _status_text(self) -> str:
        # one column short of the width: a line that fills the last column wraps on some
        # terminals, and the carriage return would then rewrite only its second half
        return "\r" + self._status[: max(1, self._columns() - 1)] + _ERASE_LINE

    def set_status(self, text: str) -> None:
        """Show ``text`` as the status line (a terminal only; elsewhere nothing)."""
        if not self.is_terminal():
            return
        self.acquire()
        try:
            self._status = text.replace("\n", " ")
            self._write(self._status_text())
        except (OSError, ValueError):  # the terminal went away: the run goes on
            self._status = ""
        finally:
            self.release()

    def clear_status(self) -> None:
        """Erase the status line, if one is shown."""
        self.acquire()
        try:
            if self._status:
                self._status = ""
                self._write("\r" + _ERASE_LINE)
        except (OSError, ValueError):
            pass
        finally:
            self.release()


def stderr_handler() -> StderrHandler | None:
    """The handler ``command_logging`` installed (None outside an ``fbs`` command)."""
    for h in logging.getLogger().handlers:
        if isinstance(h, StderrHandler):
            return h
    return None


@contextmanager
def command_logging(verbose: bool) -> Iterator[StderrHandler]:
    """For the block: project loggers at INFO (DEBUG if ``verbose``), everything else at WARNING,
    on stderr with timestamps; warnings logged. Undone afterwards (``main`` may be called more
    than once in a process, as the tests and ``fbs batch`` do)."""
    root = logging.getLogger()
    handler = StderrHandler()
    restore_levels = set_levels(verbose)
    root.addHandler(handler)
    logging.captureWarnings(True)
    try:
        yield handler
    finally:
        logging.captureWarnings(False)
        handler.clear_status()
        root.removeHandler(handler)
        restore_levels()
