"""``<run>.log`` beside each run file: every log record of the run, timestamped, whatever the
terminal showed - for ``fbs run``, ``fbs demo`` and a procedure run from the console alike.

The file's name is only known once the run's arguments have been checked and the rig opened
(bad input must fail before any output is created), yet the header and the rig's opening are
part of the story. ``RunLog`` therefore holds the command's records in memory from its start
and writes them out when ``open`` names the file; from then on records go straight to it.
The levels are the process's (``drivers.logrule``): the project's INFO (DEBUG with ``-v``) and
other libraries' warnings, plus the plain progress lines. An exception that ends the block
leaves its traceback here (not on stderr) and a note on the exception naming the file, which
``fbs.cli`` reports an internal error with.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from types import TracebackType

from drivers.logrule import Formatter, ProjectFilter

log = logging.getLogger(__name__)

#: records held before the file is named (a run's setup logs a few dozen)
MAX_HELD = 10_000


class _Held(logging.Handler):
    def __init__(self) -> None:
        super().__init__()
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        if len(self.records) < MAX_HELD:
            record.msg, record.args = (
                record.getMessage(),
                None,
            )  # as it reads now, not when written out
            self.records.append(record)


class RunLog:
    """``with RunLog() as runlog: ... runlog.open(path) ...``: the block's log records, in ``path``
    once it is opened (those before it included); nothing is written if it never is."""

    def __init__(self) -> None:
        self._held: _Held | None = _Held()
        self._file: logging.FileHandler | None = None
        self.path: Path | None = None

    def __enter__(self) -> RunLog:
        assert self._held is not None
        logging.getLogger().addHandler(self._held)
        return self

    def open(self, path: Path) -> Path:
        """Write the held records to ``path`` (appended to: an earlier log is never lost), then
        every record until the block ends."""
        from daq.runfile import make_folder

        make_folder(path.parent, "the log's folder")
        handler = logging.FileHandler(path, mode="a", encoding="utf-8", errors="backslashreplace")
        handler.setFormatter(Formatter())
        handler.addFilter(ProjectFilter())
        root = logging.getLogger()
        if self._held is not None:
            root.removeHandler(self._held)
            for record in self._held.records:
                handler.handle(record)
            self._held = None
        root.addHandler(handler)
        self._file, self.path = handler, path
        return path

    def follow(self, run_file: Path | None) -> Path | None:
        """Rename the log to sit beside ``run_file`` if the run wrote another name than the one
        foreseen (another process took that name in between); the open file is kept."""
        if self.path is None or run_file is None:
            return self.path
        wanted = run_file.with_suffix(".log")
        if wanted != self.path and not wanted.exists():
            try:
                os.replace(self.path, wanted)
                self.path = wanted
            except OSError as exc:
                log.warning(
                    "the run's log stays %s (not renamed to %s: %s)", self.path, wanted, exc
                )
        return self.path

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if isinstance(exc, Exception) and self._file is not None:
            # the traceback of what ended the run belongs with the run; stderr gets it only
            # with -v, so the command line's one line says where it is (fbs.cli)
            log.error(
                "the run ended by %s", type(exc).__name__, exc_info=exc, extra={"stderr": False}
            )
            exc.add_note(f"its traceback is in {self.path}")
        root = logging.getLogger()
        if self._held is not None:
            root.removeHandler(self._held)
            self._held = None
        if self._file is not None:
            root.removeHandler(self._file)
            self._file.close()
            self._file = None
