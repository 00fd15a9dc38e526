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

    def show(self, snap: Snapshot) -> None:
        rec = snap.recording
        st = snap.relay
        spin = (f"{100 * st.spin_fraction:.0f}" if st is not None and st.mode >= 2 and not all(st.at_speed.values())
                else None)
        key = (snap.relay, snap.phase, snap.fault, snap.alarm, self.note,
               int(rec.elapsed_s) if rec else None,
               round(100 * snap.procedure.fraction) if snap.procedure else None,
               spin and duration(snap.spin_left_s))
        if key == self._shown:
            return
        self._shown = key
        # the lamps first, the rig's URL last: a narrow terminal cuts the end of the line
        t = Text(no_wrap=True, overflow="ellipsis")
        if st is not None:
            t.append(f" MODE {st.mode} ", style="bold reverse")
            t.append(f" {MODES.get(st.mode, '?')[:22]} ")
            if st.held:
                t.append(" HELD ", style="bold black on yellow")
            if spin is not None:
                t.append(f" wheels {spin} %" + (f", ~{duration(snap.spin_left_s)} " if snap.spin_left_s is not None
                                                  else " "), style="yellow")
        else:
            t.append(f" {snap.phase} ")
        if snap.fault:
            t.append(" FAULT ", style="bold white on red")
        elif snap.alarm:
            t.append(" ALARM ", style="bold white on red")
        if snap.phase == "recording" and snap.recording is not None:
            t.append(f" REC {snap.recording.elapsed_s:.0f} s ", style="bold white on red")
        if snap.procedure is not None:
            t.append(f" {snap.procedure.name} {100 * snap.procedure.fraction:.0f} % ", style="bold black on cyan")
        if self.note:
            t.append(f" {self.note}", style="bold yellow")
        t.append(f"  {self.url}", style="dim")
        self.update(t, layout=False)
