"""The procedure panel: pick a procedure, edit its parameters (k=v, as ``fbs run --param``),
run it with a progress bar, step and time remaining, a live log and an abort key; the
summary (verdict, status, file, measurements) at the end."""

from __future__ import annotations

import dataclasses
import json
import shlex
from typing import TYPE_CHECKING, ClassVar

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.message import Message
from textual.widgets import Input, ProgressBar, RichLog, Select, Static

from console.keyhelp import PanelHelp
from console.state import ProcedureInfo

if TYPE_CHECKING:
    from procedures.runner import Procedure


def _fmt_s(s: float | None) -> str:
    if s is None:
        return "?"
    if s >= 3600:
        return f"{s / 3600:.1f} h"
    if s >= 90:
        return f"{s / 60:.0f} min"
    return f"{s:.0f} s"


def defaults_text(proc_cls: type[Procedure]) -> str:
    """The parameters and their defaults, as ``k=v`` pairs a user can copy."""
    return " ".join(f"{k}={json.dumps(v, separators=(',', ':'))}"
                    for k, v in dataclasses.asdict(proc_cls.Params()).items())


def parse_param_text(proc_cls, text: str):
    """``k=v k=v`` (values as in ``fbs run --param``: JSON when it parses) -> the procedure."""
    from procedures.params import parse_params

    try:
        specs = shlex.split(text, posix=False)  # keep quotes: values are JSON (channels=["X"])
    except ValueError as exc:
        raise ValueError(f"parameters {text!r}: {exc}") from None
    return proc_cls(parse_params(proc_cls, specs, None))


class ProcedurePanel(Vertical, can_focus=True):
    KEY_HELP: ClassVar[PanelHelp] = (
        ("F7", "run the chosen procedure with the typed parameters (name=value ..., as fbs run --param)"),
        ("F8", "abort it: the rig goes safe, its file is closed \"aborted\" (fbs run --resume continues it)"),
        ("Tab / shift+Tab", "between the procedure list and the parameters box"),
        ("Enter", "on the list: open it; in the parameters box: run"),
    )
    BINDINGS = [Binding("f7", "run", "run"), Binding("f8", "abort", "abort")]

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

    def compose(self) -> ComposeResult:
        with Horizontal(classes="proc-row"):
            yield Select([], prompt="loading…", id="proc-name", compact=True)
            yield Input(placeholder="parameters: name=value ... (f7 run, f8 abort)", id="proc-params", compact=True)
        yield Static(id="proc-defaults")
        with Horizontal(classes="proc-row"):
            yield ProgressBar(total=100, show_eta=False, id="proc-bar")
            yield Static("idle", id="proc-step")
        yield RichLog(id="proc-log", max_lines=1000, wrap=False, markup=False)
        yield Static(id="proc-result")

    def set_catalogue(self, catalogue: dict[str, type[Procedure]]) -> None:
        """The procedures (imported off the UI thread: the analysis stack takes seconds)."""
        self.catalogue = catalogue
        select = self.query_one("#proc-name", Select)
        select.set_options([(n, n) for n in catalogue])
        if catalogue:
            select.value = next(iter(catalogue))
        self._show_defaults()

    def on_select_changed(self, event: Select.Changed) -> None:
        event.stop()
        self._show_defaults()

    def _show_defaults(self) -> None:
        name = self.query_one("#proc-name", Select).value
        if isinstance(name, str) and name in self.catalogue:
            cls = self.catalogue[name]
            self.query_one("#proc-defaults", Static).update(Text(f"{cls.title}\ndefaults: {defaults_text(cls)}",
                                                                 overflow="ellipsis", no_wrap=True))

    def action_run(self) -> None:
        name = self.query_one("#proc-name", Select).value
        self.post_message(self.Run(str(name), self.query_one("#proc-params", Input).value))

    def action_abort(self) -> None:
        self.post_message(self.Abort())

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self.action_run()

    def started(self, name: str) -> None:
        self.running = True
        self.query_one("#proc-log", RichLog).clear()
        self.query_one("#proc-result", Static).update("")
        self.query_one("#proc-bar", ProgressBar).update(progress=0)
        self.query_one("#proc-step", Static).update(f"{name}: starting")

    def show(self, info: ProcedureInfo | None) -> None:
        if info is None:
            return
        self.query_one("#proc-bar", ProgressBar).update(progress=100 * info.fraction)
        left = f"about {_fmt_s(info.remaining_wall_s)} left" if info.remaining_wall_s is not None else (
            f"{_fmt_s(info.remaining_rig_s)} of rig time left")
        step = (f"step {info.index + 1}/{info.n_steps} {info.step} · {left}" if info.n_steps else info.step)
        if info.aborting:
            step = "ABORTING (rig going safe) · " + step
        self.query_one("#proc-step", Static).update(Text(step, no_wrap=True, overflow="ellipsis"))

    def log_lines(self, lines: list[str]) -> None:
        log = self.query_one("#proc-log", RichLog)
        for line in lines:
            log.write(Text(line, style="red" if line.startswith(("E ", "C ")) else ""))

    def finished(self, summary) -> None:
        self.running = False
        ok = summary.verdict == "pass"
        t = Text()
        t.append(f" {summary.verdict.upper()} ", style="bold white on " + ("green" if ok else "red"))
        t.append(f" {summary.procedure}: status {summary.status}\n file {summary.file}\n")
        for m in summary.measurements[:6]:
            mark = {True: "pass", False: "FAIL", None: ""}[m.passed]
            val = f"{m.value:.6g}" if m.value is not None else "-"
            t.append(f" {m.name}: {val} {m.units} {mark}\n")
        if summary.error:
            t.append(f" error: {summary.error}", style="red")
        self.query_one("#proc-result", Static).update(t)
        self.query_one("#proc-step", Static).update(f"{summary.procedure}: {summary.verdict} ({summary.status})")
