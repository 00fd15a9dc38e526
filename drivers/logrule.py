"""Which log records this program shows, and how each line reads: one rule for every place
that logs (the command line's stderr and run logs, ``fbs.logsetup``; the console's
``console.log`` and live log, ``console.app``).

* This project's packages (``PROJECT_PACKAGES``) from INFO (DEBUG on request), every other
  library's only from WARNING: the CANopen stack logs each SDO transfer at INFO ("Expedited
  upload for 0x6411:02"), 98 % of a console session's log before this rule.
* ``set_levels`` sets the loggers so: other libraries' INFO records are not even made.
  ``ProjectFilter`` on each handler holds the rule whatever a host or a library sets its
  loggers to afterwards (the console used to set the root logger to INFO).
* A line: ``2026-11-29 05:38:15.874+0000 INFO drivers.rig: ...``, local time with its UTC
  offset, so lines from hosts in other zones, or from either side of a DST change, compare.

It lives in the lowest layer so that every layer can use it (the console may not import
``fbs``).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

#: the packages of this project: their records are shown from INFO (DEBUG with ``-v``)
PROJECT_PACKAGES = ("fbs", "drivers", "simhw", "daq", "procedures", "console")
LINE_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


def is_project(name: str) -> bool:
    """``name`` is a logger of this project's packages."""
    return name.split(".", 1)[0] in PROJECT_PACKAGES


class ProjectFilter(logging.Filter):
    """Passes this project's records and other libraries' from WARNING."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.levelno >= logging.WARNING or is_project(record.name)


class Formatter(logging.Formatter):
    """``LINE_FORMAT`` with the time as ``YYYY-mm-dd HH:MM:SS.mmm+hhmm`` (local, its offset)."""

    def __init__(self, fmt: str = LINE_FORMAT) -> None:
        super().__init__(fmt)

    def formatTime(self, record: logging.LogRecord, datefmt: str | None = None) -> str:
        t = time.localtime(record.created)
        ms = int(record.msecs)
        return f"{time.strftime('%Y-%m-%d %H:%M:%S', t)}.{ms:03d}{time.strftime('%z', t)}"


def set_levels(verbose: bool = False) -> Callable[[], None]:
    """Root logger at WARNING, this project's at INFO (DEBUG if ``verbose``); returns what
    restores the levels found (a process may run several commands: the tests, ``fbs batch``)."""
    root = logging.getLogger()
    saved = {name: logging.getLogger(name).level for name in PROJECT_PACKAGES}
    saved_root = root.level
    root.setLevel(logging.WARNING)
    for name in PROJECT_PACKAGES:
        logging.getLogger(name).setLevel(logging.DEBUG if verbose else logging.INFO)

    def restore() -> None:
        root.setLevel(saved_root)
        for name, level in saved.items():
            logging.getLogger(name).setLevel(level)

    return restore


def ruled(handler: logging.Handler) -> logging.Handler:
    """``handler`` with the project's line format and ``ProjectFilter``."""
    handler.setFormatter(Formatter())
    handler.addFilter(ProjectFilter())
    return handler
