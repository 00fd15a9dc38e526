"""A procedure's progress on the command line: one live line on a terminal, plain timestamped
lines at a modest rate everywhere else (a pipe, a file, the run's log).

The runner reports progress after every few seconds of rig time, which on the simulated rig
in virtual time is hundreds of times a second. The live line is redrawn at most
``REDRAW_S`` apart (and at each new step or phase); a plain line is written at each new step
and phase (analysing, writing report, done), each ``PLAIN_STEP`` of the bar, and at least every
``PLAIN_HEARTBEAT_S`` of wall time, so an overnight run's log stays readable and still shows it
is alive. The fraction is the runner's (``procedures.progress``: monotone by construction).
"""

from __future__ import annotations

import logging
import math
import time
from pathlib import Path
from typing import Any

from drivers.rig import Rig
from fbs.logsetup import StderrHandler, stderr_handler
from procedures.procedure import Procedure
from procedures.progress import STEPS, Progress
from procedures.resume import Resumed, run_file_for
from procedures.runlog import RunLog
from procedures.runner import RunSummary, run_procedure

log = logging.getLogger("fbs.run_progress")

REDRAW_S = 0.2
PLAIN_STEP = 0.1
PLAIN_HEARTBEAT_S = 300.0
BAR_WIDTH = 12


def fmt_duration(seconds: float | None) -> str:
    """``42s``, ``12m05s``, ``3h02m``; ``?`` when not known yet."""
    if seconds is None or not math.isfinite(seconds):
        return "?"
    s = max(0, int(round(seconds)))
    if s < 60:
        return f"{s}s"
    if s < 3600:
        return f"{s // 60}m{s % 60:02d}s"
    return f"{s // 3600}h{s % 3600 // 60:02d}m"


def describe(p: Progress) -> str:
    """What a progress report says, in one line: a step, or a phase after the steps."""
    if p.phase != STEPS:
        return f"{p.procedure}: {100 * p.fraction:3.0f} %, {p.phase}"
    return (
        f"{p.procedure}: {100 * p.fraction:3.0f} %, step {p.index + 1}/{p.n_steps} {p.step}; "
        f"left: rig {fmt_duration(p.remaining_rig_s)}, wall ~{fmt_duration(p.remaining_wall_s)}"
    )


def bar(fraction: float, width: int = BAR_WIDTH) -> str:
    filled = int(round(max(0.0, min(1.0, fraction)) * width))
    return "[" + "#" * filled + "-" * (width - filled) + "]"


class ProgressReporter:
    """A ``procedures.progress.ProgressListener`` for the command line. ``handler`` is the
    command's stderr handler (``fbs.logsetup.stderr_handler()``); without one (or off a
    terminal) only the plain lines are written. ``close`` erases the live line."""

    def __init__(self, handler: StderrHandler | None) -> None:
        self._handler = handler if handler is not None and handler.is_terminal() else None
        self._t0 = time.monotonic()
        self._last_draw = -math.inf
        self._last_plain = -math.inf
        self._step: tuple[int, str] | None = None  # the step shown last (live line)
        self._plain_step: tuple[int, str] | None = None  # ... and written last (plain line)
        self._next_mark = 0.0

    def __call__(self, p: Progress) -> None:
        now = time.monotonic()
        step = (p.index, p.step)
        if self._handler is not None and (step != self._step or now - self._last_draw >= REDRAW_S):
            self._step, self._last_draw = step, now
            # the bar first and the elapsed time last: a narrow terminal cuts the end
            self._handler.set_status(
                f"{bar(p.fraction)} {describe(p)}; {fmt_duration(now - self._t0)} elapsed"
            )
        if (
            step != self._plain_step
            or p.fraction >= self._next_mark
            or now - self._last_plain >= PLAIN_HEARTBEAT_S
        ):
            self._plain_step, self._last_plain = step, now
            self._next_mark = (math.floor(p.fraction / PLAIN_STEP + 1e-9) + 1) * PLAIN_STEP
            log.info("%s", describe(p), extra={"progress": True})

    def close(self) -> None:
        if self._handler is not None:
            self._handler.clear_status()

    @property
    def elapsed_s(self) -> float:
        return time.monotonic() - self._t0


def run_with_progress(
    proc: Procedure[Any], rig: Rig, out: Path, runlog: RunLog, *, resume: Resumed | None = None
) -> RunSummary:
    """``run_procedure`` as the command line runs it: ``runlog`` opened as ``<run>.log`` beside
    the run file (a complete run analysed again: its own log, appended to), progress on the
    status line and in plain lines."""
    runlog.open(run_file_for(out, proc.name, resume).with_suffix(".log"))
    reporter = ProgressReporter(stderr_handler())
    try:
        summary = run_procedure(proc, rig, out, resume=resume, progress=reporter)
    finally:
        reporter.close()
    runlog.follow(summary.file)
    return summary
