"""The procedure panel: pick a procedure, edit its parameters (k=v, as ``fbs run --param``),
run it with a progress bar, step and time remaining, a live log and an abort key; at the end
the whole summary (verdict, status, every measurement, the run file, report and plots, and for
an unfinished run how to resume it). Parameters and results that do not fit scroll."""

from __future__ import annotations

import dataclasses
import json
import math
import re
import shlex
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.message import Message
from textual.widgets import Input, ProgressBar, Select, Static

from console.eventlog import EventLog
from console.keyhelp import PanelHelp
from console.keyorder import OrderedInput
from console.state import ProcedureInfo
from console.timefmt import duration

if TYPE_CHECKING:
    from procedures.procedure import Measurement, Procedure
    from procedures.runner import RunSummary


RESUME = "--resume"
#: the procedure list's value until the catalogue is loaded: no procedure's name
LOADING = ""


def defaults_text(proc_cls: type[Procedure]) -> str:
    """Every parameter and its default, as ``k=v`` pairs a user can copy (``  `` between them,
    so a narrow panel wraps between pairs, never inside one)."""
    return "  ".join(
        f"{k}={json.dumps(v, separators=(',', ':'))}"
        for k, v in dataclasses.asdict(proc_cls.Params()).items()
    )


def parse_param_text(proc_cls, text: str):
    """``k=v k=v`` (values as in ``fbs run --param``: JSON when it parses) -> the procedure."""
    from procedures.params import parse_params

    return proc_cls(parse_params(proc_cls, _split(text), None))


def parse_run_text(proc_cls, text: str) -> tuple[Procedure, Path | None]:
    """The parameters box: ``k=v ...`` (a new run), or ``--resume FILE`` (continue that aborted
    run with its own parameters, as ``fbs run NAME --resume FILE``): the procedure and the file."""
    specs = _split(text)
    if RESUME not in specs:
        return parse_param_text(proc_cls, text), None
    if len(specs) != 2 or specs[0] != RESUME:
        raise ValueError(
            f"{RESUME} FILE continues the interrupted run with its own parameters: "
            "give the file alone, no name=value"
        )
    return proc_cls(), Path(specs[1].strip('"'))


def _split(text: str) -> list[str]:
    try:
        return shlex.split(text, posix=False)  # keep quotes: values are JSON (channels=["X"])
    except ValueError as exc:
        raise ValueError(f"parameters {text!r}: {exc}") from None


def can_resume(summary: RunSummary) -> bool:
    """An unfinished run whose file exists: ``fbs run --resume`` continues it."""
    return summary.status != "complete" and summary.file is not None and summary.file.exists()


#: the interval the procedures write into a measurement's note ("95 % [1.2, 3.4]")
_INTERVAL = re.compile(r"95 % \[[^\]]*\]")


def value_text(m: Measurement) -> Text:
    """A measurement's value, error and units; a figure the procedure could not resolve says
    so (its note: "not resolved: ..."), with the interval where the note gives one, rather
    than a bare "-": an unresolved figure is a result, not a missing row."""
    unresolved = "not resolved" in m.note
    interval = _INTERVAL.search(m.note) if unresolved else None
    t = Text()
    if m.value is None and unresolved:
        t.append("not resolved", style="bold yellow")
        if interval:
            t.append(f" {interval[0]} {m.units}".rstrip())
        return t
    val = f"{m.value:.6g}" if m.value is not None else "-"
    err = f" ± {m.stderr:.3g}" if m.stderr is not None and math.isfinite(m.stderr) else ""
    t.append(f"{val}{err} {m.units}".rstrip())
    if unresolved:  # a value given, but its interval too wide to call it measured
        t.append(" (not resolved)", style="bold yellow")
    return t


def result_text(summary: RunSummary, plots: tuple[Path, ...] = ()) -> Text:
    """The whole summary: verdict and status, every measurement (value, error, limits, pass or
    FAIL), the files written, the error, and how to resume an unfinished run."""
    ok = summary.verdict == "pass"
    t = Text()
    t.append(f" {summary.verdict.upper()} ", style="bold white on " + ("green" if ok else "red"))
    t.append(f" {summary.procedure}: status {summary.status}")
    if summary.steps_planned:
        t.append(f"; {len(summary.steps_done)} of {len(summary.steps_planned)} steps done")
    t.append("\n")
    if summary.error:
        t.append(f"error: {summary.error}\n", style="red")
    if summary.measurements:
        t.append(f"{len(summary.measurements)} measurement(s):\n", style="bold")
    for m in summary.measurements:
        t.append(f"  {m.name}: ")
        t.append_text(value_text(m))
        if m.limits_text():
            t.append(f"  limits {m.limits_text()}", style="dim")
        if m.passed is not None:
            t.append("  pass" if m.passed else "  FAIL", style="green" if m.passed else "bold red")
        t.append("\n")
    for label, path in (
        ("file", summary.file),
        ("report", summary.report),
        *(("plot", p) for p in plots),
    ):
        if path is not None:
            t.append(f"{label:<7}", style="bold")
            t.append(f"{path}\n")
    if can_resume(summary):
        t.append("resume ", style="bold")
        t.append(f"f9 here, or: fbs run {summary.procedure} {RESUME} {summary.file}\n")
        t.append(
            "       (the steps done are taken over, the run's own parameters kept)", style="dim"
        )
    t.rstrip()
    return t


class ProcedurePanel(Vertical, can_focus=True):
    KEY_HELP: ClassVar[PanelHelp] = (
        (
            "F7",
            "run the chosen procedure with the typed parameters (name=value ..., as fbs run --param), "
            "or continue an aborted run: --resume FILE",
        ),
        (
            "F8",
            'abort it: the rig goes safe, its file is closed "aborted" (F9 or --resume continues it)',
        ),
        (
            "F9",
            "resume the run just aborted (its parameters, the steps done taken over), as fbs run --resume",
        ),
        (
            "Tab / shift+Tab",
            "between the list, the parameters box, the parameter list, the log and the result",
        ),
        ("up / down", "on the parameter list, the log or the result: scroll it"),
        ("Enter", "on the list: open it; in the parameters box: run"),
    )
    BINDINGS = [
        Binding("f7", "run", "run"),
        Binding("f8", "abort", "abort"),
        Binding("f9", "resume", "resume"),
    ]

    class Run(Message):
        def __init__(self, name: str, params: str) -> None:
            super().__init__()
            self.name, self.params = name, params

    class Abort(Message):
        pass

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.catalogue: dict[str, type[Procedure]] = {}
        self.running = False
        #: the unfinished run F9 continues: (procedure, file)
        self.resumable: tuple[str, Path] | None = None
        #: the running step's line as last shown (None: the step line shows something else)
        self._step_line: str | None = None

    def compose(self) -> ComposeResult:
        with Horizontal(classes="proc-row"):
            # no blank entry ever: a blank's prompt could be chosen, and named no procedure
            # ("Select.NULL"); until the catalogue is in, one disabled "loading…" entry
            yield Select(
                [("loading…", LOADING)],
                allow_blank=False,
                value=LOADING,
                disabled=True,
                id="proc-name",
                compact=True,
            )
            yield OrderedInput(
                placeholder="parameters: name=value ... (f7 run, f8 abort)",
                id="proc-params",
                compact=True,
            )
        with VerticalScroll(id="proc-about"):
            yield Static(id="proc-defaults")
        with Horizontal(classes="proc-row"):
            yield ProgressBar(total=100, show_eta=False, id="proc-bar")
            yield Static("idle", id="proc-step")
        # wrapped (re-wrapped when its width changes): no horizontal scroll bar, no line cut off
        yield EventLog(
            id="proc-log", max_lines=1000, wrap=True, min_width=20, markup=False, auto_scroll=True
        )
        with VerticalScroll(id="proc-result-box"):
            yield Static(id="proc-result")

    def set_catalogue(self, catalogue: dict[str, type[Procedure]]) -> None:
        """The procedures (imported off the UI thread: the analysis stack takes seconds)."""
        self.catalogue = catalogue
        select = self.query_one("#proc-name", Select)
        if catalogue:  # the placeholder goes: the first procedure is chosen
            select.set_options([(n, n) for n in catalogue])
            select.disabled = False
        else:
            select.set_options([("no procedures", LOADING)])
        self._show_defaults()

    def on_select_changed(self, event: Select.Changed) -> None:
        event.stop()
        self._show_defaults()

    def _show_defaults(self) -> None:
        name = self.query_one("#proc-name", Select).value
        if isinstance(name, str) and name in self.catalogue:
            cls = self.catalogue[name]
            n = len(dataclasses.fields(cls.Params))
            t = Text(f"{cls.title}\n", style="bold")
            t.append(f"{n} parameters, defaults: ", style="")
            t.append(defaults_text(cls), style="")
            self.query_one("#proc-defaults", Static).update(t)

    def action_run(self) -> None:
        name = self.query_one("#proc-name", Select).value
        self.post_message(self.Run(str(name), self.query_one("#proc-params", Input).value))

    def action_abort(self) -> None:
        self.post_message(self.Abort())

    def action_resume(self) -> None:
        if self.resumable is None:
            self.app.notify(
                "no aborted run to resume here: type --resume FILE in the parameters box",
                severity="warning",
                timeout=6,
            )
            return
        name, path = self.resumable
        self.query_one("#proc-name", Select).value = name
        self.post_message(self.Run(name, f"{RESUME} {path}"))

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self.action_run()

    def started(self, name: str, resuming: Path | None = None) -> None:
        self.running = True
        self.add_class("-ran")
        self.query_one("#proc-log", EventLog).clear()
        self.query_one("#proc-result", Static).update("")
        self.query_one("#proc-bar", ProgressBar).update(progress=0)
        self._set_step(f"{name}: {'resuming ' + str(resuming) if resuming else 'starting'}")

    def refused(self, text: str) -> None:
        """The run did not start (the rig thread refused it): the panel is idle again."""
        self.running = False
        self._set_step(Text(f"not started: {text}", style="red"))

    def show(self, info: ProcedureInfo | None) -> None:
        if info is None:
            return
        self.query_one("#proc-bar", ProgressBar).update(progress=100 * info.fraction)
        left = (
            f"about {duration(info.remaining_wall_s)} left"
            if info.remaining_wall_s is not None
            else (f"{duration(info.remaining_rig_s)} of rig time left")
        )
        step = (
            f"step {info.index + 1}/{info.n_steps} {info.step} · {left}"
            if info.n_steps
            else info.step
        )
        if info.phase != "steps":  # after the steps: the analysis, the report
            step = f"{info.phase} (all {info.n_steps} steps done)"
        if info.aborting:
            step = "ABORTING (rig going safe) · " + step
        if step == self._step_line:
            return
        # One line cut with an ellipsis, refreshed with the live state (12 a second): its height
        # never changes, so no layout pass over the whole screen - those were most of the
        # console's CPU during a run, and the simulated rig shares that CPU.
        self._set_step(
            Text(step, no_wrap=True, overflow="ellipsis"), layout=self._step_line is None
        )
        self._step_line = step

    def _set_step(self, content: str | Text, *, layout: bool = True) -> None:
        """Show ``content`` on the step line (a layout pass unless told it keeps its size)."""
        self._step_line = None
        self.query_one("#proc-step", Static).update(content, layout=layout)

    def log_lines(self, lines: list[str]) -> None:
        log = self.query_one("#proc-log", EventLog)
        for line in lines:
            log.add(Text(line, style="red" if line.startswith(("E ", "C ")) else ""))

    def finished(self, summary: RunSummary, plots: tuple[Path, ...] = ()) -> None:
        self.running = False
        self.add_class("-ran")
        self.resumable = (
            (summary.procedure, summary.file) if can_resume(summary) and summary.file else None
        )
        self.query_one("#proc-result", Static).update(result_text(summary, plots))
        self.query_one("#proc-result-box", VerticalScroll).scroll_home(animate=False)
        self._set_step(
            Text(
                f"{summary.procedure}: {summary.verdict} (below)", no_wrap=True, overflow="ellipsis"
            )
        )
