"""The recording panel: start/stop with a file name, elapsed time, samples, gaps; event log."""

from __future__ import annotations

import time
from pathlib import Path
from typing import ClassVar

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.message import Message
from textual.widgets import Input, Static

from console.eventlog import EventLog
from console.keyhelp import PanelHelp
from console.keyorder import OrderedInput
from console.state import RecordingInfo, RigEventItem, Snapshot


class RecordingPanel(Vertical, can_focus=True):
    KEY_HELP: ClassVar[PanelHelp] = (
        (
            "F7",
            "start a recording: the file (blank: the next free recording.h5, named in "
            "the box; a name goes into --out, an absolute path as typed), rate, channels "
            "(all, or names as gyro_x,torq_x)",
        ),
        ("F8", 'stop it: the file is closed "complete"'),
        ("Tab / shift+Tab", "the next / previous box"),
        ("Enter", "in a box: start the recording"),
    )
    BINDINGS = [Binding("f7", "start", "record"), Binding("f8", "stop", "stop")]

    class Start(Message):
        def __init__(self, path: str, rate: str, channels: str) -> None:
            super().__init__()
            self.path, self.rate, self.channels = path, rate, channels

    class Stop(Message):
        pass

    def compose(self) -> ComposeResult:
        with Horizontal(classes="rec-row"):
            yield Static("file", classes="rec-label")
            yield OrderedInput(
                placeholder="blank: the next free recording.h5", id="rec-path", compact=True
            )
        with Horizontal(classes="rec-row"):
            yield Static("rate Hz", classes="rec-label")
            yield OrderedInput("1000", id="rec-rate", compact=True, classes="rec-short")
            yield Static(" channels", classes="rec-label")
            yield OrderedInput(
                placeholder="all, or names: gyro_x,torq_x,...", id="rec-channels", compact=True
            )
        yield Static("not recording   (f7 record, f8 stop)", id="rec-status")
        yield Static("event log", classes="section")
        # wrapped, so no horizontal scroll bar hides the newest line; it follows the newest entry
        yield EventLog(
            id="event-log", max_lines=500, wrap=True, min_width=20, markup=False, auto_scroll=True
        )

    def set_next_path(self, path: Path) -> None:
        """The file a recording started with a blank name goes to (the name shown is the name written)."""
        self.query_one("#rec-path", Input).placeholder = f"blank: {path} (the next free name)"

    def action_start(self) -> None:
        self.post_message(
            self.Start(
                self.query_one("#rec-path", Input).value,
                self.query_one("#rec-rate", Input).value,
                self.query_one("#rec-channels", Input).value,
            )
        )

    def action_stop(self) -> None:
        self.post_message(self.Stop())

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self.action_start()

    _shown: tuple = ()

    def show(self, snap: Snapshot) -> None:
        r = snap.recording
        key = (
            snap.phase,
            r.status if r else None,
            round(r.elapsed_s, 1) if r else None,
            r.gaps if r else None,
        )
        if key == self._shown:
            return
        self._shown = key
        status = self.query_one("#rec-status", Static)
        if r is None:
            status.update("not recording   (f7 record, f8 stop)")
        elif snap.phase == "recording" and r.status == "recording":
            t = Text()
            t.append(" ● REC ", style="bold white on red")
            t.append(
                f" {r.path}\n elapsed {_hms(r.elapsed_s)}   samples {r.samples}   "
                f"{len(r.channels)} ch at {r.rate_hz:g} Hz   gaps {r.gaps} ({r.lost} lost)"
            )
            status.update(t, layout=False)
        else:
            status.update(_ended(r), layout=False)

    _last_text = ""

    def log_events(self, items: list[RigEventItem]) -> None:
        """One line an event: wall clock, rig time, kind, text; a text the line before already
        said (a refused mode after its alarm) is not repeated."""
        log = self.query_one("#event-log", EventLog)
        for e in items:
            if e.text == self._last_text or e.text.endswith(": " + self._last_text):
                continue  # e.g. "select mode 7: <the alarm's text>" right after that alarm
            self._last_text = e.text
            log.add(event_line(e))


def event_line(e: RigEventItem) -> Text:
    """``12:03:07 r  1234.56 s alarm    mode 7 is not allowed ...`` (wall clock, then rig time)."""
    wall = time.strftime("%H:%M:%S", time.localtime(e.wall_s))
    rig = f"r {e.rig_time_s:9.2f} s" if e.rig_time_s is not None else "r         - s"
    style = (
        "bold red"
        if e.kind in ("alarm", "error", "fault")
        else "red"
        if e.kind == "refused"
        else "yellow"
        if e.kind == "gap"
        else ""
    )
    t = Text(f"{wall} ", style="dim")
    t.append(f"{rig} ", style="dim")
    t.append(f"{e.kind:<8} {e.text}", style=style)
    return t


def _hms(s: float) -> str:
    s = max(0.0, s)
    return f"{int(s // 3600):02d}:{int(s % 3600 // 60):02d}:{s % 60:04.1f}"


def _ended(r: RecordingInfo) -> Text:
    t = Text(f"last recording {r.path}: ")
    t.append(r.status, style="green" if r.status == "complete" else "bold red")
    t.append(f"\n {_hms(r.elapsed_s)}, {r.samples} samples, {r.gaps} gap(s)   (f7 record again)")
    return t


def recording_path(typed: str, out_dir: Path) -> Path:
    """The file a recording goes to: blank is ``default_path``; a name or a relative path
    typed goes into the console's ``--out`` folder, as every other file the console writes
    (the shell's working directory is no place the operator can see); an absolute path (or
    ``~``) is taken as typed."""
    typed = typed.strip()
    if not typed:
        return default_path(out_dir)
    path = Path(typed).expanduser()
    return path if path.is_absolute() else out_dir / path


def default_path(out_dir: Path) -> Path:
    """The next free ``recording.h5`` name in ``out_dir`` (a recording is never overwritten)."""
    from procedures.resume import next_free

    return next_free(out_dir, "recording")
