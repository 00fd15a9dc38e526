"""What a procedure author uses: ``Procedure`` (a plan of ``Step`` objects and an ``analyze``),
the ``Context`` a step sees, the ``Measurement``/``Figure``/``Analysis`` it concludes with, the
provenance ``Span`` of a data step's samples, the ``Verdict`` and the errors that end a run.

A procedure is a plan: a plain list of ``Step`` objects, each a name, a plain function of the
run's ``Context`` and the rig time it is expected to take. The list is made before step 1 (its
length and expected times drive the progress and the time remaining); a step that depends on an
earlier one reads ``Context.results`` when it runs. The executor (``procedures.runner``) runs the
plan inside one continuous recording and, after the last step, the procedure's ``analyze`` turns
the step results and the data spans into measurements, which are checked against their limits
(as OpenHTF's measurements with validators) for the pass/fail verdict.

Provenance is the runner's: for every data step it records where its samples are (``Span``: the
run file and the sample range), hands them to ``analyze`` (``Context.spans``,
``Context.data_spans``) and carries them over on resume, so no procedure keeps its own
bookkeeping of files and times.
"""

from __future__ import annotations

import abc
import dataclasses
import math
import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Generic, Literal, TypeVar, overload

import numpy as np

from daq.recorder import Acquisition
from drivers.rig import Rig
from procedures import paramtypes
from procedures.analysis.intervals import finite_json
from procedures.progress import ANALYSIS_SHARE, ProgressListener, ProgressModel
from procedures.stepresult import StepResult

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

EVENT_STEP = "step"
EVENT_STEP_DONE = "step-done"
EVENT_MEASUREMENT = "measurement"


class ProcedureAborted(Exception):
    """The operator (or a supervisor) asked the procedure to stop."""


class ProcedureError(Exception):
    """The procedure cannot go on: what happened and what to do, in words."""


class StepResultTooLarge(ProcedureError):
    """A step's result whose ``step-done`` event would not fit the run file's event text
    (``daq.runfile.TEXT_BYTES``): a cut result could not be resumed from, so the run aborts
    (to the safe state) rather than record it. A bug in the procedure: fewer fields, or fewer
    ``StepResult.digits``."""

    def __init__(self, procedure: str, step: str, size: int, limit: int) -> None:
        self.procedure, self.step, self.size, self.limit = procedure, step, size, limit
        super().__init__(
            f"{procedure}: step {step!r}: its result is {size} bytes of JSON, more than an "
            f"event holds ({limit}); keep step results small"
        )


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
#: what a step returns
R = TypeVar("R", bound=StepResult)


@dataclass
class Step(Generic[R]):
    """One named step of a plan: ``run(ctx)`` returns its result, a ``result`` instance."""

    name: str
    run: Callable[[Context], R]
    #: expected rig seconds, for progress and time remaining
    expected_s: float = 1.0
    #: a setup step puts the rig in a state and runs again on resume; a data step is taken over
    setup: bool = False
    #: the type ``run`` returns: a resume reads the recorded result back as it
    result: type[R] = field(kw_only=True)


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
    def plan(self) -> Sequence[Step[Any]]:
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
        self.results: dict[str, StepResult] = {}
        #: where each data step's samples are (resumed steps: in the earlier file), by step name
        self.spans: dict[str, Span] = {}
        self._progress = progress
        self._abort = abort
        self.step: Step[Any] | None = None
        self.index = 0
        self.steps: list[Step[Any]] = []
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

    def result(self, step: str, kind: type[R]) -> R:
        """The result of the step ``step`` done (run or taken over), as its type ``kind``."""
        got = self.results.get(step)
        if not isinstance(got, kind):
            raise ProcedureError(
                f"{self.proc.name}: step {step!r} has no {kind.__name__} result (got {got!r})"
            )
        return got

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
