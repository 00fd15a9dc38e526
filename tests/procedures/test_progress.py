"""Issue 37 item 4, acceptance B: progress never runs backwards and names its analysing phase.

The rule is ``procedures.progress``: weights fixed from the plan's ``expected_s``, a step clamped
to its weight, a finished or resumed step counted whole. Tested on the model itself with steps
that overrun, undershoot and are skipped, and through ``run_procedure`` for every procedure in
the catalogue: its real plan, run on a stand-in recording whose steps take 0.5x, 1x and 3x
their expected time (in random order) and, once, a resume. The old runner counted a finished
step twice at its boundary (the step's time and then its weight) and so ran backwards there
whenever a step had taken any rig time; it also stood at 100 % through the analysis.
"""

from __future__ import annotations

import logging
import random
from functools import partial
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import procedures.runner as runner
from drivers.rig_datasheet import RigCalibration
from procedures.calibrations import catalogue
from procedures.procedure import Analysis, Step
from procedures.progress import ANALYSING, DONE, STEPS, WRITING_REPORT, Progress, ProgressModel
from procedures.resume import Resumed
from procedures.runner import run_procedure
from procedures.stepresult import Recorded

FACTORS = (0.5, 1.0, 3.0)


def assert_monotone_then_done(seen: list[Progress], caplog, *, report: bool) -> None:
    """Non-decreasing by the rule (the model's last guard never fired), the steps, then
    "analysing" (and "writing report") below 1.0, and 1.0 only at the end, "done"."""
    fractions = [p.fraction for p in seen]
    assert all(b >= a for a, b in zip(fractions, fractions[1:])), fractions
    assert not [r for r in caplog.records if "held back" in r.getMessage()]
    phases = [p.phase for p in seen]
    after = [ANALYSING, WRITING_REPORT, DONE] if report else [ANALYSING, DONE]
    assert phases[-len(after) :] == after and set(phases[: -len(after)]) == {STEPS}, phases
    assert seen[-1].fraction == 1.0 and max(fractions[:-1]) < 1.0


# ---------------------------------------------------------------------------- the model itself
def _drive(model: ProgressModel, actual_s: list[float | None], chunk_s: float = 1.0) -> None:
    """Each step running ``actual_s`` rig seconds in chunks (None: taken over on resume)."""
    t = 0.0
    for i, d in enumerate(actual_s):
        model.in_step(i, 0.0, t)
        if d is not None:
            t0 = t
            while t - t0 < d:
                t = min(t + chunk_s, t0 + d)
                model.in_step(i, t - t0, t)
        model.step_done(i, t)
    model.phase(ANALYSING, t)
    model.phase(WRITING_REPORT, t)
    model.phase(DONE, t)


@pytest.mark.parametrize(
    "actual",
    [
        [25.0, 2.0, 90.0],  # overrun, undershoot, overrun: the bar waits, then jumps
        [10.0, 20.0, 30.0],  # as expected
        [None, 40.0, None],  # the first and last taken over (resume)
        [0.0, 0.0, 0.0],  # steps that take no rig time (a mode already in force)
    ],
    ids=["over-under", "exact", "resumed", "instant"],
)
def test_the_model_is_monotone_and_analyses_before_100(actual, caplog):
    seen: list[Progress] = []
    model = ProgressModel(
        "p", [("a", 10.0), ("b", 20.0), ("c", 30.0)], seen.append, analysis_share=0.1
    )
    with caplog.at_level(logging.WARNING, "procedures.progress"):
        _drive(model, actual)
    assert_monotone_then_done(seen, caplog, report=True)
    # a finished step counts its whole weight, however long it really took
    start_c = next(p for p in seen if p.step == "c")
    assert start_c.fraction == pytest.approx(
        0.9 * 30 / 60
    ) and start_c.remaining_rig_s == pytest.approx(30.0)
    assert next(p for p in seen if p.phase == ANALYSING).fraction == pytest.approx(0.9)


def test_an_overrun_holds_the_bar_within_its_step():
    seen: list[Progress] = []
    model = ProgressModel("p", [("settle", 10.0), ("data", 10.0)], seen.append, analysis_share=0.0)
    model.in_step(0, 5.0, 5.0)
    model.in_step(0, 50.0, 50.0)  # a settle that waits five times longer
    assert [p.fraction for p in seen] == [0.25, 0.5]
    model.step_done(0, 50.0)
    model.in_step(1, 0.0, 50.0)
    assert [p.fraction for p in seen[-2:]] == [0.5, 0.5]


def test_plans_without_weights_still_move_and_listeners_cannot_break_the_run(caplog):
    seen: list[Progress] = []
    model = ProgressModel("p", [("a", 0.0), ("b", float("nan"))], seen.append)
    model.step_done(0, 0.0)
    assert seen[-1].fraction == pytest.approx(0.95 / 2)
    empty: list[Progress] = []
    ProgressModel("p", [], empty.append).phase(DONE, 0.0)
    assert empty[-1].fraction == 1.0

    def broken(p: Progress) -> None:
        raise RuntimeError("listener bug")

    ProgressModel("p", [("a", 1.0)], broken).in_step(0, 0.5, 0.5)  # logged, not raised
    assert "progress listener failed" in caplog.text


def test_the_last_guard_holds_a_backward_step_and_says_so(caplog):
    seen: list[Progress] = []
    model = ProgressModel("p", [("a", 10.0), ("b", 10.0)], seen.append)
    model.step_done(1, 20.0)
    model.in_step(0, 1.0, 21.0)  # misuse: an earlier step after a later one
    assert seen[-1].fraction == seen[-2].fraction
    assert "a bug in the progress rule" in caplog.text


# ---------------------------------------------------------------------------- every procedure
class StandInAcquisition:
    """``daq.recorder.Acquisition`` as far as the runner uses it: rig time is the sample count
    at 1 Hz and passes only as a step acquires; events are dropped."""

    def __init__(self, rig, path, *, rate_hz, channels, **kw) -> None:
        self.rate_hz, self.channels, self.pos = 1.0, tuple(channels), 0
        self.result = SimpleNamespace(path=Path(path), status="recording")

    def __enter__(self) -> StandInAcquisition:
        return self

    def __exit__(self, et, exc, tb) -> None:
        self.result.status = "complete" if exc is None else f"aborted: {exc}"

    @property
    def time_s(self) -> float:
        return self.pos / self.rate_hz

    def note(self, kind: str, text: str, time_s: float | None = None) -> None:
        pass

    def acquire_samples(self, n: int, *, keep: bool = True) -> np.ndarray | None:
        self.pos += n
        return np.zeros((n, len(self.channels))) if keep else None


def _takes(ctx, *, seconds: float) -> Recorded:
    # a few chunks per step, as a real step's acquisitions report
    ctx.acquire(seconds, keep=False, chunk_s=max(1.0, seconds / 7))
    return Recorded(seconds=seconds)


def _run_synthetic(
    name: str,
    factors: list[float],
    tmp_path: Path,
    caplog,
    *,
    taken_over: frozenset[str] | set[str] = frozenset(),
) -> list[Progress]:
    proc = catalogue()[name]()
    real = list(proc.plan())  # the procedure's own plan, default parameters, no rig
    proc.plan = lambda: [
        Step(
            s.name,
            partial(_takes, seconds=f * s.expected_s),
            s.expected_s,
            s.setup,
            result=Recorded,
        )
        for s, f in zip(real, factors)
    ]
    proc.analyze = lambda ctx: Analysis({}, [])
    resume = (
        Resumed(tmp_path / "earlier.h5", name, {}, {n: Recorded(seconds=0.0) for n in taken_over})
        if taken_over
        else None
    )
    seen: list[Progress] = []
    rig = SimpleNamespace(
        calibration=RigCalibration(),
        check=lambda: None,
        url="stand-in",
        simulated=True,
        sim_config=None,
    )
    caplog.clear()
    with caplog.at_level(logging.WARNING, "procedures.progress"):
        s = run_procedure(proc, rig, tmp_path, progress=seen.append, resume=resume, report=False)
    assert s.status == "complete" and s.steps_resumed == [
        x.name for x in real if x.name in taken_over
    ]
    assert_monotone_then_done(seen, caplog, report=False)
    return seen


@pytest.mark.parametrize("name", sorted(catalogue()))
def test_every_procedure_progresses_monotonically_however_long_its_steps_take(
    name, tmp_path, monkeypatch, caplog
):
    monkeypatch.setattr(runner, "Acquisition", StandInAcquisition)
    rng = random.Random(name)
    n = len(catalogue()[name]().plan())
    orders = [rng.sample(FACTORS, 3) for _ in range(n)]  # each step takes each factor once
    for trial in range(3):
        _run_synthetic(name, [o[trial] for o in orders], tmp_path / f"t{trial}", caplog)
    # a resume: some data steps taken over (their whole weight at once), the rest run
    data = [s.name for s in catalogue()[name]().plan() if not s.setup]
    taken = {d for d in data if rng.random() < 0.5} or set(data[:1])
    _run_synthetic(
        name,
        [rng.choice(FACTORS) for _ in range(n)],
        tmp_path / "resumed",
        caplog,
        taken_over=taken,
    )
