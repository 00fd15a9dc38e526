"""A procedure's progress: one monotone fraction, fixed by the plan before step 1.

The rule (issue 37): every step weighs its ``expected_s`` (rig seconds), set when the plan is
made and never re-estimated. Of the bar, ``1 - analysis_share`` is the steps' and the rest the
analysis's and the report's, which take wall time but no rig time. A step's progress within
itself is its rig time so far, clamped to its weight (a settle that waits longer holds the bar,
it does not push into the next step's share); a finished step counts its whole weight, however
long it really took, and so does a step taken over on resume. The fraction is therefore a sum of
non-decreasing terms: monotone by construction. A ``max`` with the last fraction shown guards
against a caller's misuse, not against the rule.

After the steps come named phases at fixed points of the analysis share: ``analysing`` (at
``1 - analysis_share``), ``writing report`` (``REPORT_PART`` of the share before the end), then
``done`` at exactly 1.0, which only a finished run reaches. Every display (the status line of
``fbs run`` and its plain lines, the console's header and procedure panel) shows this one
object's fraction and computes none of its own.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

log = logging.getLogger(__name__)

#: the phases a ``Progress`` names: the steps, then the analysis, the report, and the end
STEPS, ANALYSING, WRITING_REPORT, DONE = "steps", "analysing", "writing report", "done"

#: the default part of the bar kept for the analysis and the report (a procedure may set its own
#: ``analysis_share``): they take no rig time, so their weight cannot come from ``expected_s``
ANALYSIS_SHARE = 0.05
#: the part of the analysis share the report takes (it starts this much before the end)
REPORT_PART = 0.4


@dataclass(frozen=True)
class Progress:
    procedure: str
    step: str  # the current step's name; in a later phase, the phase's
    index: int  # 0-based index of the current step (the last one after the steps)
    n_steps: int
    fraction: float  # 0..1, monotone; 1.0 only when the run has finished
    elapsed_rig_s: float
    remaining_rig_s: float
    remaining_wall_s: float | None  # from the rig-time speed seen so far (None until measurable)
    phase: str = STEPS  # STEPS, ANALYSING, WRITING_REPORT or DONE


ProgressListener = Callable[[Progress], None]


class ProgressModel:
    """The progress of one run of a plan (``(name, expected_s)`` per step), told to ``listener``.
    The runner calls ``in_step`` as rig time passes, ``step_done`` at each step's end (a resumed
    step included), ``phase`` for the analysis and the report, and ``phase(DONE)`` at the end."""

    def __init__(
        self,
        procedure: str,
        plan: Sequence[tuple[str, float]],
        listener: ProgressListener | None,
        *,
        analysis_share: float = ANALYSIS_SHARE,
        rig_t0_s: float = 0.0,
    ) -> None:
        self.procedure = procedure
        self.names = [name for name, _ in plan]
        # a weight that is not a positive number counts nothing; a plan of only such steps
        # weighs each step alike, so the bar still moves
        w = [float(s) if math.isfinite(s) and s > 0 else 0.0 for _, s in plan]
        self.weights = w if sum(w) > 0 else [1.0] * len(w)
        self.total_s = sum(self.weights) or 1.0
        self._before = [sum(self.weights[:i]) for i in range(len(self.weights) + 1)]
        self.steps_share = 1.0 - min(max(analysis_share, 0.0), 1.0)
        self._listener = listener
        self._rig0, self._wall0 = rig_t0_s, time.monotonic()
        self._shown = 0.0

    def fraction_of(self, index: int, in_step_s: float | None) -> float:
        """The fraction at rig time ``in_step_s`` into step ``index`` (None: the step is done)."""
        return self.steps_share * self._weight_done(index, in_step_s) / self.total_s

    def _weight_done(self, index: int, in_step_s: float | None) -> float:
        if not self.weights:
            return 0.0
        w = self.weights[index]
        return self._before[index] + (w if in_step_s is None else min(max(in_step_s, 0.0), w))

    def in_step(self, index: int, in_step_s: float, rig_now_s: float) -> None:
        self._steps(index, in_step_s, rig_now_s)

    def step_done(self, index: int, rig_now_s: float) -> None:
        self._steps(index, None, rig_now_s)

    def phase(self, name: str, rig_now_s: float) -> None:
        """A phase after the steps: its fixed point of the analysis share; ``DONE`` is 1.0."""
        share = 1.0 - self.steps_share
        at = {ANALYSING: self.steps_share, WRITING_REPORT: 1.0 - share * REPORT_PART, DONE: 1.0}[
            name
        ]
        self._emit(
            Progress(
                self.procedure,
                name,
                max(len(self.names) - 1, 0),
                len(self.names),
                at,
                rig_now_s,
                0.0,
                None,
                name,
            )
        )

    def _steps(self, index: int, in_step_s: float | None, rig_now_s: float) -> None:
        done = self._weight_done(index, in_step_s)
        remaining = self.total_s - done
        wall = time.monotonic() - self._wall0
        rig_run = rig_now_s - self._rig0
        speed = rig_run / wall if wall > 1.0 and rig_run > 0 else None
        name = self.names[index] if self.names else ""
        self._emit(
            Progress(
                self.procedure,
                name,
                index,
                len(self.names),
                self.steps_share * done / self.total_s,
                rig_now_s,
                remaining,
                remaining / speed if speed else None,
            )
        )

    def _emit(self, p: Progress) -> None:
        if p.fraction < self._shown:  # the last guard only: the rule above is monotone
            log.warning(
                "progress %.4f after %.4f held back (%s): a bug in the progress rule",
                p.fraction,
                self._shown,
                p.step,
            )
            p = replace(p, fraction=self._shown)
        self._shown = p.fraction
        if self._listener is None:
            return
        try:
            self._listener(p)
        except Exception:  # a listener's trouble is not the procedure's
            log.exception("progress listener failed")
