"""The procedure runner: named steps, progress, measurements with limits, abort to safe.

A procedure (``Procedure``) is a plan: a plain list of ``Step`` objects, each a name, a plain
function of the run's ``Context`` and the rig time it is expected to take. The list is made
before step 1 (its length and expected times drive the progress and the time remaining); a
step that depends on an earlier one reads ``Context.results`` when it runs. The runner
executes the plan inside one continuous recording (``daq.recorder.Acquisition``), so every
command and every sample of the procedure lands in one "fbs-run" file with a ``step`` event
at each step's start and a ``step-done`` event, carrying the step's JSON result and the span
of samples it recorded, at its end. After the last step the procedure's ``analyze`` turns the
step results and the data spans into measurements, which are checked against their limits
(as OpenHTF's measurements with validators) for the pass/fail verdict.

Provenance is the runner's: for every data step it records where its samples are (``Span``:
the run file and the sample range), hands them to ``analyze`` (``Context.spans``,
``Context.data_spans``) and carries them over on resume, so no procedure keeps its own
bookkeeping of files and times.

Abort: Ctrl-C, an exception, a device fault or ``Context.abort`` (the console's button) ends
the run. The runner owns the teardown (as OpenHTF's executor does): the rig goes to the safe
state (``drivers.safety.SafeOnAbort``) while the file is still open, then the recording is
closed "aborted: <why>"; the summary lists the steps done. ``resume`` starts a new run from an
aborted file: its completed data steps are taken over (their results and spans re-recorded as
``step-done`` events marked ``resumed``), setup steps run again, the rest run normally.
``resume`` of a complete file (``load_resume(..., complete_ok=True)``) moves nothing: its
analysis runs again and its summary and report are written anew (an analysis or report that
was interrupted or failed after a complete acquisition).

Outputs: the report first, the JSON summary last (atomically), so a summary never claims a
report that is not there. Ctrl-C (or SIGTERM/SIGHUP as ``KeyboardInterrupt``) during the
analysis or the report makes the verdict "aborted" and the summary says what was not written.
"""

from __future__ import annotations

import abc
import dataclasses
import json
import logging
import math
import signal
import threading
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Generic, Literal, TypeVar, overload

import numpy as np

from daq import provenance
from daq.reader import Event, RunFile
from daq.recorder import Acquisition
from daq.runfile import STATUS_COMPLETE, TEXT_BYTES, RunFileError, abort_status, make_folder
from drivers.rig import Rig
from drivers.safety import SafeOnAbort
from procedures import paramtypes
from procedures.analysis.intervals import finite_json
from procedures.progress import ANALYSING, ANALYSIS_SHARE, DONE, WRITING_REPORT, ProgressModel
from procedures.progress import Progress as Progress  # re-exported: listeners import it here
from procedures.progress import ProgressListener as ProgressListener

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

log = logging.getLogger(__name__)

EVENT_STEP = "step"
EVENT_STEP_DONE = "step-done"
EVENT_MEASUREMENT = "measurement"


class ProcedureAborted(Exception):
    """The operator (or a supervisor) asked the procedure to stop."""


class ProcedureError(Exception):
    """The procedure cannot go on: what happened and what to do, in words."""


class Verdict(StrEnum):
    """How a run ended. A ``str``, so summaries and JSON read as before ("pass", ...)."""

    PASS = "pass"  # every measurement within its limits
    FAIL = "fail"  # the run completed, a measurement is outside its limits
    ABORTED = "aborted"  # stopped before its end (operator, Ctrl-C, device fault)
    ERROR = "error"  # could not start, or its analysis failed

    @property
    def exit_code(self) -> int:
        """DESIGN.md section 7: 0 pass, 1 limits failed, 2 aborted or error."""
        return {Verdict.PASS: 0, Verdict.FAIL: 1}.get(self, 2)


# ---------------------------------------------------------------------------- measurements
@dataclass
class Measurement:
    """One measured value with its limits; ``passed`` is None when it has no limits."""

    name: str
    value: float | None
    units: str = ""
    lo: float | None = None
    hi: float | None = None
    stderr: float | None = None
    note: str = ""

    @property
    def passed(self) -> bool | None:
        if self.lo is None and self.hi is None:
            return None
        if self.value is None or not math.isfinite(self.value):
            return False
        return bool(
            (self.lo is None or self.value >= self.lo)
            and (self.hi is None or self.value <= self.hi)
        )

    def limits_text(self) -> str:
        if self.lo is not None and self.hi is not None:
            return f"{self.lo:.6g} .. {self.hi:.6g}"
        if self.lo is not None:
            return f">= {self.lo:.6g}"
        if self.hi is not None:
            return f"<= {self.hi:.6g}"
        return ""

    def to_json(self) -> dict[str, Any]:
        return finite_json(dataclasses.asdict(self) | {"passed": self.passed})


@dataclass
class Figure:
    """A plot for the report: ``draw(path)`` writes a PNG there."""

    name: str
    caption: str
    draw: Callable[[Path], object]


@dataclass
class Analysis:
    """What a procedure concludes: the JSON summary values (DESIGN.md section 7), the
    measurements with limits, figures and free Markdown for the report."""

    values: dict[str, Any]
    measurements: list[Measurement] = field(default_factory=list)
    figures: list[Figure] = field(default_factory=list)
    markdown: str = ""


# ---------------------------------------------------------------------------- provenance
@dataclass(frozen=True)
class Span:
    """Where a data step's samples are: samples ``start <= i < stop`` of the run ``file``."""

    file: Path
    start: int
    stop: int
    rate_hz: float

    @property
    def samples(self) -> int:
        return self.stop - self.start

    def to_json(self, recorded_in: Path | None = None) -> dict[str, Any]:
        """With ``recorded_in`` (the run file this is written into), a data file beside it is
        named by its name alone: the step's event then fits whatever the directory's depth."""
        beside = recorded_in is not None and self.file.parent == Path(recorded_in).resolve().parent
        return {
            "file": self.file.name if beside else str(self.file),
            "start": self.start,
            "stop": self.stop,
            "rate_hz": self.rate_hz,
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any], recorded_in: Path) -> Span:
        """A span read from the file ``recorded_in``: a bare name is beside it; a data file that
        is no longer where it was recorded is looked for beside it (a run directory copied
        elsewhere)."""
        path = Path(data["file"])
        if not path.is_absolute():
            path = recorded_in.parent / path
        elif not path.exists() and (recorded_in.parent / path.name).exists():
            path = recorded_in.parent / path.name
        return cls(path, int(data["start"]), int(data["stop"]), float(data["rate_hz"]))


def merge_spans(spans: Iterable[Span]) -> list[Span]:
    """The spans in order, back-to-back spans of one file joined into one continuous stretch."""
    out: list[Span] = []
    for s in spans:
        if (
            out
            and out[-1].file == s.file
            and out[-1].stop == s.start
            and out[-1].rate_hz == s.rate_hz
        ):
            out[-1] = Span(s.file, out[-1].start, s.stop, s.rate_hz)
        else:
            out.append(s)
    return out


# ---------------------------------------------------------------------------- steps, progress
@dataclass
class Step:
    name: str
    run: Callable[[Context], Any]
    #: expected rig seconds, for progress and time remaining
    expected_s: float = 1.0
    #: a setup step puts the rig in a state and runs again on resume; a data step is taken over
    setup: bool = False


# ---------------------------------------------------------------------------- procedure
#: a procedure's parameters: a dataclass, one per procedure
P = TypeVar("P", bound="DataclassInstance")


class Procedure(abc.ABC, Generic[P]):
    """A scripted procedure, generic over its parameters' dataclass ``P``. Subclasses set the
    class attributes (``Params`` is ``P`` itself, for building defaults and parsing
    ``--param``) and write ``plan`` and ``analyze``; ``procedures.calibrations.catalogue``
    finds them by their module's ``PROCEDURE``."""

    name: ClassVar[str]  # CLI name, e.g. "earth-rate"
    title: ClassVar[str]
    json_keys: ClassVar[tuple[str, ...]]  # DESIGN.md section 7, "file" included
    Params: ClassVar[type[Any]]  # the dataclass P (a ClassVar cannot name a type variable)
    #: the mode the procedure measures in (the run file's ``mode``); a parameter may choose it
    mode: int = 3
    #: its runs in ``fbs demo``'s campaign, each (axis or None, its ``--param`` settings), and
    #: their place: the campaign runs the catalogue by ``demo_order`` (a procedure that uses
    #: another's result comes after it), so a new procedure joins it by itself, once, with its
    #: defaults, after the thesis's seven; ``demo_runs = ()`` leaves it out
    demo_runs: ClassVar[tuple[tuple[str | None, tuple[str, ...]], ...]] = ((None, ()),)
    demo_order: ClassVar[int] = 1000

    def __init__(
        self, params: P | None = None, *, prior: Mapping[str, Mapping[str, Any]] | None = None
    ) -> None:
        self.params: P = params if params is not None else self.Params()
        #: summaries of earlier procedures (by name), e.g. the earth-rate K_TO a stopwatch run uses
        self.prior = dict(prior or {})

    # what to record
    @abc.abstractmethod
    def channels(self) -> tuple[str, ...]: ...

    rate_hz: float = 100.0
    block_s: float = 1.0
    axis: str | None = None
    #: ADC full-scale ranges (+-V) per channel; None: the largest
    ranges_V: dict[str, float] | None = None
    #: the part of the progress bar kept for the analysis and report (``procedures.progress``)
    analysis_share: float = ANALYSIS_SHARE

    @abc.abstractmethod
    def plan(self) -> Sequence[Step]:
        """The steps, in order: a plain list, made before step 1. A step that depends on an
        earlier one reads ``ctx.results`` when it runs."""

    @abc.abstractmethod
    def analyze(self, ctx: Context) -> Analysis:
        """After the steps: measurements from ``ctx.results`` and the data steps' samples
        (``ctx.spans``, ``ctx.data_spans``)."""

    def headline(self) -> dict[str, tuple[str, ...]]:
        """The headline figures (keys of ``json_keys``, bookkeeping and ``file`` left out) and
        the channels each is reported for, known from the parameters before the run: the
        ``--json`` keeps this shape on every path, an abort included, and a run with none of
        them measured is no pass (``headline_measurement``). Empty: no such rule."""
        return {}

    def params_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self.params)

    @classmethod
    def params_from(cls, data: Mapping[str, Any]) -> Any:
        names = {f.name: f for f in dataclasses.fields(cls.Params)}
        unknown = sorted(set(data) - set(names))
        if unknown:
            raise ValueError(
                f"{cls.name}: unknown parameter(s) {', '.join(unknown)} (known: {', '.join(names)})"
            )
        paramtypes.check(cls.Params, data, cls.name)
        return cls.Params(**data)


# ---------------------------------------------------------------------------- context
class Context:
    """What a step sees: the rig, the recording, earlier results, and helpers that keep the
    progress current and honour an abort request."""

    #: the recording; not set when a complete run is analysed again from its file
    acq: Acquisition

    def __init__(
        self,
        proc: Procedure[Any],
        rig: Rig,
        acq: Acquisition | None,
        *,
        progress: ProgressListener | None,
        abort: threading.Event,
        path: Path | None = None,
    ) -> None:
        self.proc, self.rig = proc, rig
        self.path: Path
        if acq is not None:
            self.acq, self.path = acq, acq.result.path
        elif path is not None:
            self.path = Path(path)
        else:
            raise ValueError("a Context needs the recording or the finished run's path")
        self.params = proc.params
        self.results: dict[str, Any] = {}
        #: where each data step's samples are (resumed steps: in the earlier file), by step name
        self.spans: dict[str, Span] = {}
        self._progress = progress
        self._abort = abort
        self.step: Step | None = None
        self.index = 0
        self.steps: list[Step] = []
        self._step_t0 = 0.0  # file time the current step began
        #: the run's progress, its weights fixed from the plan when the steps start
        self._model: ProgressModel | None = None

    # time and data
    @property
    def time_s(self) -> float:
        """File time of the next sample (s)."""
        return self.acq.time_s

    @overload
    def acquire(
        self, duration_s: float, *, keep: Literal[True] = True, chunk_s: float = 5.0
    ) -> np.ndarray: ...

    @overload
    def acquire(self, duration_s: float, *, keep: Literal[False], chunk_s: float = 5.0) -> None: ...

    def acquire(
        self, duration_s: float, *, keep: bool = True, chunk_s: float = 5.0
    ) -> np.ndarray | None:
        """Acquire ``duration_s`` (all channels, (n, c) volts, NaN where lost), checking for an
        abort and reporting progress every ``chunk_s``."""
        n_total = int(round(duration_s * self.acq.rate_hz))
        chunk = max(1, int(round(chunk_s * self.acq.rate_hz)))
        out = np.empty((n_total, len(self.acq.channels))) if keep else None
        done = 0
        while done < n_total:
            self.check()
            n = min(chunk, n_total - done)
            block = self.acq.acquire_samples(n, keep=keep)
            if out is not None:
                out[done : done + n] = block
            done += n
            self.report()
        return out

    def column(self, name: str) -> int:
        return self.acq.channels.index(name)

    def data_spans(self, steps: Iterable[str] | None = None) -> list[Span]:
        """The samples of the data steps done (``steps``, default all), in plan order,
        back-to-back spans of one file joined; a step not done is left out."""
        wanted = set(self.spans) if steps is None else set(steps)
        return merge_spans(
            self.spans[s.name] for s in self.steps if s.name in wanted and s.name in self.spans
        )

    def note(self, text: str, kind: str = "note") -> None:
        self.acq.note(kind, text)

    # abort
    def check(self) -> None:
        self.rig.check()
        if self._abort.is_set():
            raise ProcedureAborted("aborted by the operator")

    # progress
    def report(self) -> None:
        if self._model is not None and self.step is not None:
            self._model.in_step(self.index, self.time_s - self._step_t0, self.time_s)

    def progress_phase(self, name: str) -> None:
        """A phase after the steps (``procedures.progress``: analysing, writing report, done)."""
        if self._model is not None:
            self._model.phase(name, self.time_s)


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


def next_free(out_dir: Path, stem: str, suffix: str = ".h5") -> Path:
    """``stem.h5``, else ``stem-2.h5``, ...: a procedure never overwrites an earlier run."""
    path = out_dir / f"{stem}{suffix}"
    n = 2
    while path.exists() or path.with_suffix(".json").exists():
        path = out_dir / f"{stem}-{n}{suffix}"
        n += 1
    return path


def run_file_for(out_dir: Path, stem: str, resume: Resumed | None = None) -> Path:
    """The file ``run_procedure`` will write: a complete run analysed again keeps its own;
    otherwise (a new run, or an aborted one resumed) the next free name."""
    return resume.path if resume is not None and resume.complete else next_free(out_dir, stem)


# ---------------------------------------------------------------------------- resume
@dataclass
class Resumed:
    path: Path
    procedure: str
    params: dict[str, Any]
    results: dict[str, Any]
    #: where the completed data steps' samples are (in that file, or in one it resumed)
    spans: dict[str, Span] = field(default_factory=dict)
    #: the run is complete: ``run_procedure`` analyses it again, the rig is not touched
    complete: bool = False
    #: the earlier results the run was made with (its /meta/prior), for analysing it again
    prior: dict[str, Any] = field(default_factory=dict)
    #: the steps that run itself took over from a run it resumed
    taken_over: list[str] = field(default_factory=list)


def load_resume(path: str | Path, procedure: str, *, complete_ok: bool = False) -> Resumed:
    """The completed steps of an aborted run of ``procedure`` (from its ``step-done`` events);
    with ``complete_ok`` a complete run too (``Resumed.complete``: to be analysed again)."""
    path = Path(path)
    with RunFile(path) as rf:
        status = rf.status
        meta = rf.meta
        events = rf.events
    info = meta.get("procedure") if isinstance(meta, dict) else None
    if not isinstance(info, dict) or "name" not in info:
        raise ProcedureError(f"--resume {path}: not a procedure run (no /meta/procedure)")
    if info["name"] != procedure:
        raise ProcedureError(
            f"--resume {path}: that file is a {info['name']!r} run, not {procedure!r}"
        )
    if status == STATUS_COMPLETE and not complete_ok:
        raise ProcedureError(f"--resume {path}: that run is complete; nothing to resume")
    results, spans = steps_done(path, events)
    prior = meta.get("prior")
    # JSON (steps_done checked it)
    done = [json.loads(e.text) for e in events if e.kind == EVENT_STEP_DONE]
    return Resumed(
        path,
        procedure,
        dict(info.get("params", {})),
        results,
        spans,
        complete=status == STATUS_COMPLETE,
        prior=dict(prior) if isinstance(prior, dict) else {},
        taken_over=[d["step"] for d in done if "resumed" in d],
    )


def steps_done(path: Path, events: Iterable[Event]) -> tuple[dict[str, Any], dict[str, Span]]:
    """The results and data spans of the steps a run file records as done (its ``step-done``
    events), by step name: what a resume takes over, or a re-analysis of a finished run reads."""
    results: dict[str, Any] = {}
    spans: dict[str, Span] = {}
    for e in events:
        if e.kind == EVENT_STEP_DONE:
            try:
                item = json.loads(e.text)
            except json.JSONDecodeError:
                raise ProcedureError(
                    f"{path}: a step-done event at {e.time_s:.3f} s is not JSON "
                    f"(cut at {len(e.text)} bytes?)"
                ) from None
            results[item["step"]] = item.get("result")
            if item.get("span"):
                spans[item["step"]] = Span.from_json(item["span"], path)
    return results, spans


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
                "result": result,
                "resumed": source.name if beside else str(source),
            }
            if step.name in resume.spans:
                ctx.spans[step.name] = resume.spans[step.name]
                done["span"] = resume.spans[step.name].to_json()
            acq.note(EVENT_STEP_DONE, _step_done_text(done))
            summary.steps_resumed.append(step.name)
        else:
            acq.note(EVENT_STEP, f"{i + 1}/{len(ctx.steps)} {step.name}")
            log.info("%s: step %d/%d: %s", proc.name, i + 1, len(ctx.steps), step.name)
            start = acq.pos
            result = step.run(ctx)
            done = {"step": step.name, "result": result}
            if not step.setup:
                ctx.spans[step.name] = Span(Path(ctx.path).resolve(), start, acq.pos, acq.rate_hz)
                done["span"] = ctx.spans[step.name].to_json(recorded_in=Path(ctx.path))
            acq.note(EVENT_STEP_DONE, _step_done_text(done))
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


def _step_done_text(done: Mapping[str, Any]) -> str:
    text = json.dumps(done, default=_jsonable, separators=(",", ":"))
    if (
        len(text.encode()) > TEXT_BYTES
    ):  # a cut result could not be resumed from: a bug in the procedure
        raise ProcedureError(
            f"step {done['step']!r}: its result is {len(text.encode())} bytes of JSON, more than "
            f"an event holds ({TEXT_BYTES}); keep step results small"
        )
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
    from procedures.reports.report import write_report
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
        with _signals_held():  # a few ms: the summary is written whole, a signal acts after it
            write_text_atomic(
                out_dir / f"{stem}.json",
                json.dumps(summary.to_json(), indent=1, default=_jsonable) + "\n",
            )
    except Exception as exc:
        log.error("%s: the summary could not be written: %s", proc.name, exc)


@contextmanager
def _signals_held() -> Iterator[None]:
    """The abort signals' handlers held back in the block and run after it (its first such
    signal), so that it is not cut short. Only the main thread runs handlers: elsewhere the
    block just runs. (Blocking with ``pthread_sigmask`` would not do: another thread takes it.)"""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    held = [getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n)]
    previous = {s: signal.signal(s, lambda signum, frame: caught.append(signum)) for s in held}
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
