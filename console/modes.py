"""The mode panel: hold, select, release (II C.2 (2), Ch. II D), the alarm lamp, interlocks."""

from __future__ import annotations

from typing import ClassVar

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Vertical
from textual.message import Message
from textual.widgets import Static

from console.keyhelp import PanelHelp
from console.state import Snapshot
from console.timefmt import duration
from drivers.relay import CAGED_FOR_MODE, MODES, RelayStatus, interlock_reason

SELECT = Binding.Group("select", compact=True)
#: the mode switches' labels, short enough for one row at 80 columns
SHORT = {1: "gyro off", 2: "spin-up", 3: "AC ctl", 4: "gyro 4ch", 5: "gyro 3ch", 6: "ext"}


class ModePanel(Vertical, can_focus=True):
    KEY_HELP: ClassVar[PanelHelp] = (
        ("h", "hold the mode switches: nothing changes until the release"),
        (
            "0-7",
            "select a mode while held: 1 gyro off, 2 spin-up, 3 autocollimator control, 4 gyro "
            "control (4-channel caging), 5 gyro control (3-channel), 6 external; 0 and 7 light the alarm",
        ),
        (
            "r",
            "release: the selected mode takes effect (4 and 5 need the gyros at speed and caged; the "
            "spin-up in mode 2 shows its time to speed)",
        ),
        (
            "s",
            "the safe state now: mode 1, outputs zero, caging released; aborts a running procedure",
        ),
    )
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("h", "hold", "hold"),
        *(Binding(str(m), f"select({m})", f"select {m}", group=SELECT) for m in range(8)),
        Binding("r", "release", "release"),
        Binding("s", "safe", "safe"),
    ]

    class Command(Message):
        """The operator asked for a mode command (``what`` is hold, select, release or safe)."""

        def __init__(self, what: str, mode: int | None = None) -> None:
            super().__init__()
            self.what, self.mode = what, mode

    def compose(self) -> ComposeResult:
        yield Static(id="mode-now")
        yield Static(id="mode-lamps")
        yield Static(id="mode-alarm")
        yield Static(id="mode-gyros")
        yield Static(id="mode-interlocks")
        yield Static(id="mode-last")
        yield Static(
            "h hold · 1-6 select (0, 7: alarm) · r release · s safe (mode 1, zero outputs)",
            id="mode-help",
        )

    def action_hold(self) -> None:
        self.post_message(self.Command("hold"))

    def action_select(self, mode: int) -> None:
        self.post_message(self.Command("select", mode))

    def action_release(self) -> None:
        self.post_message(self.Command("release"))

    def action_safe(self) -> None:
        self.post_message(self.Command("safe"))

    _shown: tuple = ()
    _last_state: tuple | None = None

    def last(self, text: str, ok: bool, snap: Snapshot | None = None) -> None:
        """The last mode command's outcome; with ``snap`` (the state just after it) the line
        goes once the mode, the switches or the alarm move on (a procedure's safe state, an
        abort, a fault): it must never say "mode 3 in force" under a header saying MODE 1."""
        self._last_state = None if snap is None else mode_state(snap)
        self.query_one("#mode-last", Static).update(Text(text, style="green" if ok else "bold red"))

    def show(self, snap: Snapshot) -> None:
        if self._last_state is not None and self._last_state != mode_state(snap):
            self.last("", True)
        key = (
            snap.relay,
            snap.alarm,
            snap.fault,
            snap.caging,
            None if snap.spin_left_s is None else duration(snap.spin_left_s),
        )
        if key == self._shown:
            return
        self._shown = key
        st = snap.relay
        if st is None:
            self.query_one("#mode-now", Static).update("mode: —")
            return
        now = Text()
        now.append(f"MODE {st.mode}", style="bold reverse")
        now.append(f"  {MODES.get(st.mode, '?')}    ")
        now.append("HELD" if st.held else "not held", style="bold yellow" if st.held else "dim")
        now.append(f"   selected {st.selected}")
        self.query_one("#mode-now", Static).update(now)
        lamps = Text()
        for m, name in SHORT.items():
            style = (
                "bold reverse green"
                if m == st.mode
                else ("underline yellow" if st.held and m == st.selected else "dim")
            )
            lamps.append(f" {m} {name} ", style=style)
            lamps.append(" ")
        self.query_one("#mode-lamps", Static).update(lamps)
        alarm = Text()
        lit = snap.alarm or (snap.fault and f"device fault: {snap.fault}")
        if lit:
            alarm.append(" ALARM ", style="bold white on red")
            alarm.append(f" {lit}", style="bold red")
        else:
            alarm.append(" alarm ", style="dim reverse")
            alarm.append(" off", style="dim")
        self.query_one("#mode-alarm", Static).update(alarm)
        self.query_one("#mode-gyros", Static).update(gyro_words(st, snap.caging, snap.spin_left_s))
        self.query_one("#mode-interlocks", Static).update(interlock_words(st, snap.alarm))


def mode_state(snap: Snapshot) -> tuple:
    """The part of the state a mode command's outcome describes."""
    st = snap.relay
    return (snap.phase, snap.alarm, snap.fault) + ((st.mode, st.held, st.selected) if st else ())


def _names(flags: dict[str, bool], want: bool) -> list[str]:
    return [c for c, v in flags.items() if v is want]


def spin_words(st: RelayStatus, left_s: float | None) -> str:
    """The wheels' speed and, spinning up, the time left to speed (estimated on rig time)."""
    text = f"wheels {100 * st.spin_fraction:.0f} %"
    if all(st.at_speed.values()):
        return text
    if st.mode < 2:
        return text + " (mode 2 spins them up)"
    return text + (
        f", at speed in about {duration(left_s)}"
        if left_s is not None
        else ", spinning up (time to speed: measuring)"
    )


def gyro_words(
    st: RelayStatus, inhibited: dict[str, bool], spin_left_s: float | None = None
) -> Text:
    """The wheels and the caging in words, and what engages the caging (II D): it is not a
    switch, the relay driver cages each gyro by itself in mode 3 once its pickoff nulls."""
    t = Text(spin_words(st, spin_left_s) + "   at speed: ")
    slow = _names(st.at_speed, False)
    t.append(
        "all"
        if not slow
        else ("none" if len(slow) == len(st.at_speed) else "all but " + " ".join(slow)),
        style="green" if not slow else "bold yellow",
    )
    t.append("   caged: ")
    loose = _names(st.caged, False)
    t.append(
        "all"
        if not loose
        else ("none" if len(loose) == len(st.caged) else "all but " + " ".join(loose)),
        style="green" if not loose else "bold yellow",
    )
    held = _names(inhibited, True)
    if loose:
        why = (
            "caging engages by itself in mode 3, each loop once its pickoff nulls"
            if st.mode < 3
            else "engaging by itself as each pickoff nulls"
            if st.mode == 3
            else ""
        )
        if held:
            why += ("; " if why else "") + f"inhibited on Set-points: {' '.join(held)}"
        if why:
            t.append(f"\n({why})", style="dim")
    return t


def interlock_words(st: RelayStatus, alarm: str | None) -> Text:
    """Whether modes 4 and 5 would be allowed now, each with what it needs. What is missing is
    said once, by the line above (at speed, caged); a refused release once more by the alarm,
    in the drivers' words (``relay.interlock_reason``), to which these lines then point."""
    t = Text()
    if st.clamped:  # the open-loop baseline's state (Ch. V B): modes 4-6 refused until released
        t.append(
            "platform CLAMPED, loops open: modes 1-3 only (fbs clamp off releases it)\n",
            style="bold yellow",
        )
    for m, need in CAGED_FOR_MODE.items():
        t.append(f"mode {m} needs {' '.join(need)} at speed and caged: ")
        if interlock_reason(m, st) is None:
            t.append("allowed", style="green")
        elif alarm is not None and alarm.startswith(f"mode {m} refused"):
            t.append("refused (the alarm says why)", style="yellow")
        else:
            t.append("not now (see above)", style="yellow")
        t.append("\n")
    t.rstrip()
    return t
