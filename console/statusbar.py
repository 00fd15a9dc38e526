"""The top line: rig, mode, alarm lamp, recording and procedure at a glance, on every panel."""

from __future__ import annotations

from rich.text import Text
from textual.widgets import Static

from console.state import Snapshot
from console.timefmt import duration
from drivers.relay import MODES


class StatusBar(Static):
    def __init__(self, url: str, **kw) -> None:
        super().__init__(**kw)
        self.url = url
        self.note = ""
        self._shown: tuple = ()
        self._lines = 1

    def show(self, snap: Snapshot) -> None:
        rec = snap.recording
        width = self.size.width
        key = (
            snap.relay,
            snap.phase,
            snap.fault,
            snap.alarm,
            self.note,
            int(rec.elapsed_s) if rec else None,
            round(100 * snap.procedure.fraction) if snap.procedure else None,
            _spin(snap) and duration(snap.spin_left_s),
            width,
        )
        if key == self._shown:
            return
        self._shown = key
        text = status_text(snap, self.url, self.note, width)
        lines = text.plain.count("\n") + 1
        self.update(text, layout=lines != self._lines)  # a second line moves the panels down
        self._lines = lines


def _spin(snap: Snapshot) -> str | None:
    st = snap.relay
    if st is None or st.mode < 2 or all(st.at_speed.values()):
        return None
    return f"{100 * st.spin_fraction:.0f}"


def status_text(snap: Snapshot, url: str, note: str = "", width: int = 0) -> Text:
    """The top line: the mode, its whole name, HELD and the wheels, then the lamps (FAULT or
    ALARM, REC, a procedure's percentage, a note), and last the rig's URL, which a narrow
    terminal cuts. A mode's name is never cut (modes 4 and 5 have 30 characters): when the
    lamps would not fit beside it in ``width`` columns they go to a second line."""
    st = snap.relay
    spin = _spin(snap)
    head = Text()
    if st is not None:
        head.append(f" MODE {st.mode} ", style="bold reverse")
        head.append(f" {MODES.get(st.mode, '?')} ")
        if st.held:
            head.append(" HELD ", style="bold black on yellow")
        if spin is not None:
            left = snap.spin_left_s
            eta = f", ~{duration(left)} " if left is not None else " "
            head.append(f" wheels {spin} %{eta}", style="yellow")
    else:
        head.append(f" {snap.phase} ")
    lamps = Text()
    if snap.fault:
        lamps.append(" FAULT ", style="bold white on red")
    elif snap.alarm:
        lamps.append(" ALARM ", style="bold white on red")
    if snap.phase == "recording" and snap.recording is not None:
        lamps.append(f" REC {snap.recording.elapsed_s:.0f} s ", style="bold white on red")
    if snap.procedure is not None:
        proc = snap.procedure
        lamps.append(f" {proc.name} {100 * proc.fraction:.0f} % ", style="bold black on cyan")
    if note:
        lamps.append(f" {note}", style="bold yellow")
    t = Text(no_wrap=True, overflow="ellipsis")
    t.append_text(head)
    if width and lamps.cell_len and head.cell_len + lamps.cell_len > width:
        t.append("\n")
    t.append_text(lamps)
    t.append(f"  {url}", style="dim")
    return t
