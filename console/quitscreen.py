"""The modal that asks before quitting closes something live (a recording, a procedure).

Quitting drives the rig safe (mode 1: the gyro wheels stop, and getting back to mode 3 takes
minutes of spin-up) and closes a recording or aborts a procedure with its file "aborted". The
operator is told which, by name, and answers y (quit) or n / Esc (keep running).
"""

from __future__ import annotations

from typing import ClassVar

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import Static

from console.state import Phase, Snapshot


def what_quit_closes(snap: Snapshot) -> list[str]:
    """What quitting now would close, in words; empty when nothing is live."""
    out: list[str] = []
    if snap.phase is Phase.RECORDING and snap.recording is not None:
        r = snap.recording
        out.append(
            f"the recording {r.path} ({r.elapsed_s:.0f} s, {r.samples} samples) is closed "
            '"aborted: ConsoleClosed"'
        )
    if snap.phase is Phase.PROCEDURE and snap.procedure is not None:
        p = snap.procedure
        where = f"step {p.index + 1}/{p.n_steps}, {100 * p.fraction:.0f} %" if p.n_steps else p.step
        out.append(
            f"the procedure {p.name} ({where}) is aborted"
            + (
                f'; its file {p.file} is closed "aborted" (fbs run --resume continues it)'
                if p.file
                else ""
            )
        )
    if out:
        st = snap.relay
        spinning = st is not None and st.spin_fraction > 0
        out.append(
            "the rig goes to the safe state (mode 1, outputs zero, caging released)"
            + (
                ": the gyro wheels stop, and back to mode 3 is minutes of spin-up"
                if spinning
                else ""
            )
        )
    return out


class QuitScreen(ModalScreen[bool]):
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("y", "answer(True)", "quit"),
        Binding("n", "answer(False)", "keep running"),
        Binding("escape", "answer(False)", "keep running"),
        Binding("q", "noop", show=False),  # a second q is not an answer
    ]

    DEFAULT_CSS = """
    QuitScreen { align: center middle; }
    QuitScreen > Vertical { width: 76; max-width: 100%; height: auto; border: thick $error;
                            background: $surface; padding: 0 1; }
    """

    def __init__(self, closes: list[str]) -> None:
        super().__init__()
        self.closes = closes

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Static("[b]Quit the console?[/b] Quitting now:")
            yield Static(Text("\n".join(f"• {line}" for line in self.closes)), id="quit-closes")
            yield Static("[b]y[/b] quit   ·   [b]n[/b] or [b]Esc[/b] keep running")

    def action_answer(self, quit_: bool) -> None:
        self.dismiss(quit_)

    def action_noop(self) -> None:
        pass
