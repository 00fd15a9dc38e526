"""The procedure executor: runs a ``procedures.procedure.Procedure``'s plan on a rig.

The runner executes the plan inside one continuous recording (``daq.recorder.Acquisition``), so
every command and every sample of the procedure lands in one "fbs-run" file with a ``step``
event at each step's start and a ``step-done`` event, carrying the step's JSON result and the
span of samples it recorded, at its end. After the last step the procedure's ``analyze`` turns
the step results and the data spans into measurements, checked against their limits for the
verdict (``RunSummary``).

Abort: Ctrl-C, an exception, a device fault or ``Context.abort`` (the console's button) ends
the run. The runner owns the teardown (as OpenHTF's executor does): the rig goes to the safe
state (``drivers.safety.SafeOnAbort``) while the file is still open, then the recording is
closed "aborted: <why>"; the summary lists the steps done. A ``resume``
(``procedures.resume.load_resume``) starts a new run from an aborted file, or analyses a
complete one again.

Outputs: the report first, the JSON summary last (atomically), so a summary never claims a
report that is not there. Ctrl-C (or SIGTERM/SIGHUP as ``KeyboardInterrupt``) during the
analysis or the report makes the verdict "aborted" and the summary says what was not written.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from daq import provenance
from daq.reader import RunFile
from daq.recorder import Acquisition
from daq.runfile import STATUS_COMPLETE, TEXT_BYTES, RunFileError, abort_status, make_folder
from drivers.rig import Rig
from drivers.safety import SafeOnAbort
from procedures.analysis.intervals import finite_dumps, finite_json
from procedures.held_signals import signals_held
from procedures.procedure import (
    EVENT_STEP,
    EVENT_STEP_DONE,
    Analysis,
    Context,
    Measurement,
    Procedure,
    ProcedureError,
    Span,
    StepResultTooLarge,
    Verdict,
)
from procedures.progress import ANALYSING, DONE, WRITING_REPORT, ProgressListener, ProgressModel
from procedures.resume import Resumed, next_free

log = logging.getLogger(__name__)


# ---------------------------------------------------------------------------- summary
@dataclass
class RunSummary:
    procedure: str
    file: Path | None
    status: str  # "complete" | "aborted: <why>"
    verdict: Verdict
    values: dict[str, Any] = field(default_factory=dict)
    measurements: list[Measurement] = field(default_factory=list)
    steps_done: list[str] = field(default_factory=list)
    steps_resumed: list[str] = field(default_factory=list)
    steps_planned: list[str] = field(default_factory=list)
    #: where each data step's samples are (the runner's provenance record)
    spans: dict[str, Span] = field(default_factory=dict)
    params: dict[str, Any] = field(default_factory=dict)
    error: str | None = None
    report: Path | None = None
    analysis: Analysis | None = None
    #: the rig, simulated or not, software and time (``daq.provenance``)
    provenance: dict[str, Any] = field(default_factory=dict)

    @property
    def exit_code(self) -> int:
        """DESIGN.md section 7: 0 pass, 1 limits failed, 2 aborted or error."""
        return self.verdict.exit_code

    def json_values(
        self, keys: tuple[str, ...], headline: Mapping[str, Sequence[str]] | None = None
    ) -> dict[str, Any]:
        """The keys of DESIGN.md section 7 (None where not measured), with each figure's
        ``K_ci95`` and the ``resolved`` map where the analysis gives them
        (``procedures.analysis.intervals.add_figure``). A ``headline`` figure has one shape
        on every path: ``{channel: value | None}``, ``K_ci95`` ``{channel: [lo, hi] | None}``
        and ``resolved[K]`` ``{channel: bool}`` (an abort: every channel None and False; a
        figure the analysis gives no interval: ``K_ci95`` None, resolved where measured)."""
        headline = {k: v for k, v in (headline or {}).items() if k in keys}
        given = self.values.get("resolved") or {}
        out: dict[str, Any] = {k: self.values.get(k) for k in keys}
        out |= {f"{k}_ci95": self.values[f"{k}_ci95"] for k in keys if f"{k}_ci95" in self.values}
        # the verdicts of the keys printed: a figure kept out of the JSON keeps its verdict out too
        resolved = {k: v for k, v in given.items() if k in keys}
        for k, channels in headline.items():
            got, ci, ok = (
                v if isinstance(v, dict) else {}
                for v in (out[k], out.get(f"{k}_ci95"), given.get(k))
            )
            chans = list(dict.fromkeys([*channels, *got]))
            out[k] = {c: got.get(c) for c in chans}
            out[f"{k}_ci95"] = {c: ci.get(c) for c in chans}
            # resolved only with a value: a null figure is never "resolved"
            resolved[k] = {c: got.get(c) is not None and bool(ok.get(c, True)) for c in chans}
        if resolved:
            out["resolved"] = resolved
        if "file" in keys:
            out["file"] = str(self.file) if self.file else None
        return finite_json(out)

    def json_result(self, proc: Procedure[Any]) -> dict[str, Any]:
        """What ``fbs run --json`` prints: the procedure, its status and verdict, where the
        result came from (``daq.provenance``), then ``json_values`` (docs/schema/)."""
        return {
            "procedure": self.procedure,
            "status": self.status,
            "verdict": str(self.verdict),
            **{k: self.provenance.get(k) for k in provenance.KEYS},
            **self.json_values(proc.json_keys, proc.headline()),
        }

    def to_json(self) -> dict[str, Any]:
        return {
            "procedure": self.procedure,
            "file": str(self.file) if self.file else None,
            "status": self.status,
            "verdict": self.verdict,
            **{k: self.provenance.get(k) for k in provenance.KEYS},
            "values": self.values,
            "measurements": [m.to_json() for m in self.measurements],
            "steps_done": self.steps_done,
            "steps_resumed": self.steps_resumed,
            "steps_planned": self.steps_planned,
            "spans": {name: s.to_json() for name, s in self.spans.items()},
            "params": self.params,
            "error": self.error,
            "report": str(self.report) if self.report else None,
        }


# ---------------------------------------------------------------------------- the runner
def run_procedure(
    proc: Procedure[Any],
    rig: Rig,
    out_dir: str | Path,
    *,
    resume: Resumed | None = None,
    progress: ProgressListener | None = None,
    abort: threading.Event | None = None,
    report: bool = True,
) -> RunSummary:
    """Run ``proc`` on ``rig``, recording to a new file in ``out_dir``; never raises for an
    abort or a failure of the procedure: the summary says what happened (exit code 2). A
    ``resume`` of a complete run analyses that run again (its summary and report beside it)."""
    if resume is not None and resume.complete:
        return _analyse_again(proc, rig, resume, abort or threading.Event(), report)
    out_dir = Path(out_dir)
    make_folder(out_dir)
    path = next_free(out_dir, proc.name)
    abort = abort or threading.Event()
    summary = RunSummary(
        proc.name,
        path,
        "aborted: not started",
        Verdict.ERROR,
        params=proc.params_json(),
        provenance=provenance.of_rig(rig),
    )
    meta = {
        "procedure": {
            "name": proc.name,
            "title": proc.title,
            "params": proc.params_json(),
            "resumed_from": str(resume.path) if resume else None,
        },
        "calibration": dataclasses.asdict(rig.calibration),
        "prior": {k: dict(v) for k, v in proc.prior.items()},
    }
    try:
        acq = Acquisition(
            rig,
            path,
            rate_hz=proc.rate_hz,
            channels=proc.channels(),
            ranges_V=proc.ranges_V,
            block_s=proc.block_s,
            procedure=proc.name,
            axis=proc.axis,
            meta=meta,
            mode=proc.mode,
        )
    except (RunFileError, OSError, ValueError) as exc:
        summary.file = None
        summary.status = f"aborted: {exc}"
        summary.error = str(exc)
        _finish_report(proc, summary, None, out_dir, report)
        return summary
    ctx = Context(proc, rig, acq, progress=progress, abort=abort)
    summary.spans = ctx.spans
    guard = SafeOnAbort(rig, proc.name)
    try:
        # the inner guard drives the rig safe while the file is open (its safe event recorded),
        # the outer one if only closing the file fails
        with guard, acq, guard:
            _execute(ctx, resume, summary)
        summary.status = acq.result.status
    except BaseException as exc:  # noqa: B036 - Ctrl-C included: the summary must say what was done
        summary.status = (
            acq.result.status if acq.result.status.startswith("aborted") else abort_status(exc)
        )
        summary.verdict = Verdict.ABORTED
        # a signal's KeyboardInterrupt carries its name (fbs.signals); Python's own Ctrl-C none
        summary.error = (
            f"interrupted ({str(exc) or 'Ctrl-C'})"
            if isinstance(exc, KeyboardInterrupt)
            else f"{type(exc).__name__}: {exc}"
        )
        log.error(
            "%s aborted in step %r: %s; rig safe: %s",
            proc.name,
            ctx.step.name if ctx.step else "-",
            summary.error,
            _safe_text(rig),
        )
        _finish_report(proc, summary, None, out_dir, report)
        return summary
    _analyse(proc, ctx, summary, out_dir, report)
    return summary


def _analyse_again(
    proc: Procedure[Any], rig: Rig, resume: Resumed, abort: threading.Event, report: bool
) -> RunSummary:
    """A complete run's analysis once more, from its file (its step results and spans); its
    summary and report are rewritten beside it. The rig is only asked for its calibration."""
    path = resume.path
    log.info("%s: %s is complete: analysing it again", proc.name, path)
    with RunFile(path) as rf:  # the data's rig, not the one asked for its calibration now
        made = provenance.of_file(rf)
    summary = RunSummary(
        proc.name, path, STATUS_COMPLETE, Verdict.ERROR, params=proc.params_json(), provenance=made
    )
    ctx = Context(proc, rig, None, progress=None, abort=abort, path=path)
    ctx.steps = list(proc.plan())
    ctx.results, ctx.spans = dict(resume.results), dict(resume.spans)
    summary.steps_planned = [s.name for s in ctx.steps]
    summary.steps_done = [s.name for s in ctx.steps if s.name in ctx.results]
    summary.steps_resumed = [n for n in summary.steps_done if n in resume.taken_over]
    summary.spans = ctx.spans
    _analyse(proc, ctx, summary, path.parent, report)
    return summary


def _analyse(
    proc: Procedure[Any], ctx: Context, summary: RunSummary, out_dir: Path, report: bool
) -> None:
    """After a complete acquisition: the analysis, the verdict, the report and the summary."""
    how_again = f"`--resume {summary.file}` analyses the complete run again"
    ctx.progress_phase(ANALYSING)
    try:
        analysis = proc.analyze(ctx)
    except KeyboardInterrupt:
        summary.verdict = Verdict.ABORTED
        summary.error = (
            f"interrupted during the analysis (the acquisition is complete); {how_again}"
        )
        _finish_report(proc, summary, None, out_dir, report)
        return
    except Exception as exc:
        log.exception("%s: analysis failed", proc.name)
        summary.verdict, summary.error = (
            Verdict.ERROR,
            f"analysis failed: {type(exc).__name__}: {exc}",
        )
        _finish_report(proc, summary, None, out_dir, report)
        return
    summary.analysis = analysis
    summary.values = analysis.values
    unmeasured = headline_measurement(proc, analysis.values)
    if unmeasured is not None:
        analysis.measurements.append(unmeasured)
    summary.measurements = analysis.measurements
    summary.verdict = (
        Verdict.FAIL if any(m.passed is False for m in analysis.measurements) else Verdict.PASS
    )
    if report:
        ctx.progress_phase(WRITING_REPORT)
    _finish_report(proc, summary, analysis, out_dir, report)
    ctx.progress_phase(DONE)


def _execute(ctx: Context, resume: Resumed | None, summary: RunSummary) -> None:
    """The steps in order, each with its events; a data step's span recorded (or taken over)."""
    proc, acq = ctx.proc, ctx.acq
    ctx.steps = list(proc.plan())
    if ctx._progress is not None:
        ctx._model = ProgressModel(
            proc.name,
            [(s.name, s.expected_s) for s in ctx.steps],
            ctx._progress,
            analysis_share=proc.analysis_share,
            rig_t0_s=acq.time_s,
        )
    summary.steps_planned = [s.name for s in ctx.steps]
    for i, step in enumerate(ctx.steps):
        ctx.index, ctx.step = i, step
        ctx._step_t0 = ctx.time_s
        ctx.check()
        ctx.report()
        if resume is not None and not step.setup and step.name in resume.results:
            result = resume.results[step.name]
            source = Path(resume.path).resolve()
            beside = source.parent == Path(ctx.path).resolve().parent
            done: dict[str, Any] = {
                "step": step.name,
                "result": result.to_json(),
                "resumed": source.name if beside else str(source),
            }
            if step.name in resume.spans:
                ctx.spans[step.name] = resume.spans[step.name]
                done["span"] = resume.spans[step.name].to_json()
            acq.note(EVENT_STEP_DONE, step_done_text(proc.name, done))
            summary.steps_resumed.append(step.name)
        else:
            acq.note(EVENT_STEP, f"{i + 1}/{len(ctx.steps)} {step.name}")
            log.info("%s: step %d/%d: %s", proc.name, i + 1, len(ctx.steps), step.name)
            start = acq.pos
            result = step.run(ctx)
            if not isinstance(result, step.result):
                raise ProcedureError(
                    f"{proc.name}: step {step.name!r} returned {type(result).__name__}, "
                    f"not the {step.result.__name__} it names"
                )
            done = {"step": step.name, "result": result.to_json()}
            if not step.setup:
                ctx.spans[step.name] = Span(Path(ctx.path).resolve(), start, acq.pos, acq.rate_hz)
                done["span"] = ctx.spans[step.name].to_json(recorded_in=Path(ctx.path))
            acq.note(EVENT_STEP_DONE, step_done_text(proc.name, done))
            # what the event holds (floats to the result's digits): the analysis of this run
            # and of a resume of it read the same result
            result = step.result.from_json(done["result"])
        ctx.results[step.name] = result
        summary.steps_done.append(step.name)
        if ctx._model is not None:  # its whole weight, however long it took (or resumed)
            ctx._model.step_done(i, ctx.time_s)


def headline_measurement(proc: Procedure[Any], values: Mapping[str, Any]) -> Measurement | None:
    """The verdict rule (README, exit codes): a run none of whose headline figures is measured
    on any channel (each None: unresolved or not made) is no pass. Then a failing measurement
    that says so (the verdict "fail", exit 1, in the text, the JSON and the report alike);
    else None."""
    headline = proc.headline()
    if not headline:
        return None
    measured = [
        v
        for k in headline
        if isinstance(values.get(k), dict)
        for v in values[k].values()
        if isinstance(v, int | float) and math.isfinite(v)
    ]  # NaN prints as null: none
    if measured:
        return None
    return Measurement(
        "headline figures measured",
        0.0,
        "",
        lo=1.0,
        note=f"none of {', '.join(headline)} resolved on any channel: not a pass",
    )


def step_done_text(procedure: str, done: Mapping[str, Any]) -> str:
    """The ``step-done`` event's text; ``StepResultTooLarge`` if it would not fit the event
    (raised inside the run's safe-state guard: the run aborts, the rig goes safe)."""
    text = json.dumps(done, default=_jsonable, separators=(",", ":"))
    size = len(text.encode())
    if size > TEXT_BYTES:  # a cut result could not be resumed from: a bug in the procedure
        raise StepResultTooLarge(procedure, str(done["step"]), size, TEXT_BYTES)
    return text


def _safe_text(rig: Rig) -> str:
    try:
        return "yes" if rig.is_safe() else "NO"
    except Exception as exc:  # the rig may be gone: say so, do not hide the abort
        return f"unknown ({exc})"


def _finish_report(
    proc: Procedure[Any],
    summary: RunSummary,
    analysis: Analysis | None,
    out_dir: Path,
    report: bool,
) -> None:
    from procedures.reports.procedure_report import write_report
    from procedures.reports.textfile import write_text_atomic

    stem = summary.file.stem if summary.file else next_free(out_dir, proc.name).stem
    summary.provenance["time"] = provenance.utc_now()  # the result's time: now it is made
    # the report first, the summary last: a summary never names a report that is not there
    if report:
        try:
            summary.report = write_report(proc, summary, analysis, out_dir / f"{stem}.md")
        except KeyboardInterrupt:  # Ctrl-C, SIGTERM or SIGHUP (fbs.signals): said, not hidden
            summary.report = None
            if summary.verdict in (Verdict.PASS, Verdict.FAIL):
                summary.verdict = Verdict.ABORTED
                summary.error = (
                    f"interrupted while the report was written (the acquisition "
                    f"and analysis are complete); no report; "
                    f"`--resume {summary.file}` analyses it again"
                )
            else:
                why = "interrupted while the report was written: no report"
                summary.error = "; ".join(filter(None, [summary.error, why]))
            log.error("%s: %s", proc.name, summary.error)
        except Exception as exc:  # a report that cannot be written must not hide the run's outcome
            log.error("%s: the report could not be written: %s", proc.name, exc)
    try:
        with signals_held():  # a few ms: the summary is written whole, a signal acts after it
            # strict JSON, as --json prints (a tool other than Python's json reads it too): an
            # infinite or undefined number is null - an interval's open end, "no bound there"
            write_text_atomic(
                out_dir / f"{stem}.json",
                finite_dumps(summary.to_json(), indent=1, default=_jsonable) + "\n",
            )
    except Exception as exc:
        log.error("%s: the summary could not be written: %s", proc.name, exc)


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return dataclasses.asdict(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serializable")
