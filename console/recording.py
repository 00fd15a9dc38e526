"""The recording panel: start/stop with a file name, elapsed time, samples, gaps; event log."""

from __future__ import annotations

from pathlib import Path

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.message import Message
from textual.widgets import Input, RichLog, Static

from console.state import RecordingInfo, RigEventItem, Snapshot


class RecordingPanel(Vertical, can_focus=True):
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
            yield Input(placeholder="out/recording.h5 (next free name)", id="rec-path", compact=True)
        with Horizontal(classes="rec-row"):
            yield Static("rate Hz", classes="rec-label")
            yield Input("1000", id="rec-rate", compact=True, classes="rec-short")
            yield Static(" channels", classes="rec-label")
            yield Input(placeholder="all (or a,b,c)", id="rec-channels", compact=True)
        yield Static("not recording   (f7 record, f8 stop)", id="rec-status")
        yield Static("event log", classes="section")
        yield RichLog(id="event-log", max_lines=500, wrap=False, markup=False)

    def action_start(self) -> None:
        self.post_message(self.Start(self.query_one("#rec-path", Input).value,
                                     self.query_one("#rec-rate", Input).value,
                                     self.query_one("#rec-channels", Input).value))

    def action_stop(self) -> None:
        self.post_message(self.Stop())

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self.action_start()

    _shown: tuple = ()

    def show(self, snap: Snapshot) -> None:
        r = snap.recording
        key = (snap.phase, r.status if r else None, round(r.elapsed_s, 1) if r else None, r.gaps if r else None)
        if key == self._shown:
            return
        self._shown = key
        status = self.query_one("#rec-status", Static)
        if r is None:
            status.update("not recording   (f7 record, f8 stop)")
        elif snap.phase == "recording" and r.status == "recording":
            t = Text()
            t.append(" ● REC ", style="bold white on red")
            t.append(f" {r.path}\n elapsed {_hms(r.elapsed_s)}   samples {r.samples}   "
                     f"{len(r.channels)} ch at {r.rate_hz:g} Hz   gaps {r.gaps} ({r.lost} lost)")
            status.update(t, layout=False)
        else:
            status.update(_ended(r), layout=False)

    def log_events(self, items: list[RigEventItem]) -> None:
        log = self.query_one("#event-log", RichLog)
        for e in items:
            stamp = f"{e.rig_time_s:10.3f} s" if e.rig_time_s is not None else " " * 12
            style = "bold red" if e.kind in ("alarm", "error", "fault") else ("yellow" if e.kind == "gap" else "")
            log.write(Text(f"{stamp} {e.kind:<9} {e.text}", style=style))


def _hms(s: float) -> str:
    s = max(0.0, s)
    return f"{int(s // 3600):02d}:{int(s % 3600 // 60):02d}:{s % 60:04.1f}"


def _ended(r: RecordingInfo) -> Text:
    t = Text(f"last recording {r.path}: ")
    t.append(r.status, style="green" if r.status == "complete" else "bold red")
    t.append(f"\n {_hms(r.elapsed_s)}, {r.samples} samples, {r.gaps} gap(s)   (f7 record again)")
    return t


def default_path(out_dir: Path) -> Path:
    """The next free ``recording.h5`` name in ``out_dir`` (a recording is never overwritten)."""
    from procedures.runner import next_free

    return next_free(out_dir, "recording")
