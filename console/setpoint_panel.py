"""The set-point panel: caging-inhibit switches, torquer biases (with slew), autocollimator
biases and command torques, each with its range and the rig's read-back.

A typed value is checked here with the drivers' own rules (``limits.SetpointLimits``); a bad
entry is refused with the drivers' message, naming the value and the limit, and nothing goes
to the rig thread. A good one is not sent yet: Enter puts the value that would be sent back
into its box ("+3", the checked number in full, not the keys as typed) and the line below says
what it will do; only Enter on that echo sends it, and any edit cancels it. A lost or
reordered key therefore shows before anything reaches the rig. Once sent (or refused) the box
is emptied: the read-back column is the only value a row shows, and a safe state, a procedure
or any change of that read-back cancels an echo not yet sent.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Horizontal, VerticalScroll
from textual.message import Message
from textual.widgets import Checkbox, Input, Static

from console.keyhelp import PanelHelp
from console.keyorder import OrderedInput
from console.limits import (
    SLEW_DEFAULT_V_PER_S,
    SLEW_MAX_V_PER_S,
    SLEW_MIN_V_PER_S,
    Entry,
    typed_setpoint,
    typed_slew,
)
from console.state import Snapshot
from drivers.errors import SetpointRangeError
from drivers.rig_datasheet import AXES, GYRO_CHANNELS
from drivers.setpoints import SetpointLimits


class SetpointPanel(VerticalScroll, can_focus=True):
    KEY_HELP: ClassVar[PanelHelp] = (
        ("Tab / shift+Tab", "the next / previous box"),
        (
            "Enter",
            "in a box: send the typed value (checked against its range first; a ramp for a torquer bias)",
        ),
        (
            "Space",
            "on a caging switch: inhibit caging on that channel / release it (read back from the node)",
        ),
        ("up / down", "scroll the panel"),
    )

    class Request(Message):
        """A checked set-point for the rig thread (or a caging switch)."""

        def __init__(self, kind: Entry, key: str, value: float | bool, slew: float = 0.0) -> None:
            super().__init__()
            self.kind, self.key, self.value, self.slew = kind, key, value, slew

    class Refused(Message):
        """An entry refused here (out of range, not a number): nothing went to the rig."""

        def __init__(self, what: str, text: str) -> None:
            super().__init__()
            self.what, self.text = what, text

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.limits: SetpointLimits | None = None
        self._back: dict[str, Static] = {}
        self._boxes: dict[str, Checkbox] = {}
        self._shown: tuple = ()
        #: box id -> the checked request its echo stands for, sent by Enter on the echo
        self._pending: dict[str, Echo] = {}
        #: the state a message describes: a later read-back or phase puts it out of date
        self._message_state: tuple | None = None

    def on_mount(self) -> None:
        # looked up once: the refresh timer runs ten times a second
        for w in self.query(".sp-back").results(Static):
            _, kind, key = (w.id or "").split("-", 2)
            self._back[f"{kind} {key}"] = w
        self._boxes = {c: self.query_one(f"#cage-{c}", Checkbox) for c in GYRO_CHANNELS}

    def compose(self) -> ComposeResult:
        with Horizontal(classes="sp-row"):
            yield Static("caging (Space)", classes="sp-label")
            for c in GYRO_CHANNELS:
                yield Checkbox(caging_label(c, False), id=f"cage-{c}", compact=True)
        yield Static(
            "  auto: the gyro cages by itself in mode 3; inhibited: its loop is held open",
            id="sp-caging-note",
        )
        yield Static(
            "torquer bias (V)   set             range           read-back", classes="sp-head"
        )
        for c in GYRO_CHANNELS:
            yield from self._row("torq", c, f"  gyro {c}")
        with Horizontal(classes="sp-row"):
            yield Static("  slew (V/s)", classes="sp-label")
            yield OrderedInput(
                f"{SLEW_DEFAULT_V_PER_S:g}", id="slew", compact=True, classes="sp-input"
            )
            yield Static(f"{SLEW_MIN_V_PER_S:g}..{SLEW_MAX_V_PER_S:g}", classes="sp-range")
        yield Static("autocollimator bias gamma_c (V)", classes="sp-head")
        for a in AXES:
            yield from self._row("gc", a, f"  axis {a}")
        yield Static("command torque V_Td (V)", classes="sp-head")
        for a in AXES:
            yield from self._row("vtd", a, f"  axis {a}")
        yield Static(id="sp-message")

    def _row(self, kind: str, key: str, label: str) -> ComposeResult:
        with Horizontal(classes="sp-row"):
            yield Static(label, classes="sp-label")
            yield OrderedInput(
                placeholder="volts", id=f"{kind}-{key}", compact=True, classes="sp-input"
            )
            yield Static("", id=f"range-{kind}-{key}", classes="sp-range")
            yield Static("—", id=f"back-{kind}-{key}", classes="sp-back")

    def set_limits(self, limits: SetpointLimits) -> None:
        self.limits = limits
        for c in GYRO_CHANNELS:
            self.query_one(f"#range-torq-{c}", Static).update(
                f"+-{limits.torquer_limit_V(c):.4g} V"
            )
        for a in AXES:
            for kind in ("gc", "vtd"):
                self.query_one(f"#range-{kind}-{a}", Static).update(
                    f"+-{limits.calibration.dac_range_V:g} V"
                )

    def message(self, text: str, ok: bool, state: tuple | None = None) -> None:
        """The panel's message line; with ``state`` (``state_key`` of the snapshot it
        describes) it is cleared once the rig's state moves on."""
        self._message_state = state
        self.query_one("#sp-message", Static).update(
            Text(text, style="green" if ok else "bold red")
        )

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        box = event.input
        if self.limits is None or box.id is None:
            self.message("the rig is not open yet", False)
            return
        prefix, _, key = box.id.partition("-")
        kind = Entry(prefix)
        echo = self._pending.pop(box.id, None)
        if echo is not None and event.value == echo.text:
            box.value = ""  # sent: the read-back column shows what the rig took
            self.message(f"sent: {echo.words}", True)
            self.post_message(self.Request(echo.kind, echo.key, echo.value, echo.slew))
            return
        try:
            if kind is Entry.SLEW:
                rate = typed_slew(event.value)
                self.message(f"torquer bias slew {rate:g} V/s", True)
                return
            rate = typed_slew(self.query_one("#slew", Input).value)
            value = typed_setpoint(self.limits, kind, key, event.value)
        except SetpointRangeError as exc:  # refused here: nothing goes to the rig
            box.value = ""
            self.message(f"refused: {exc}", False)
            self.post_message(self.Refused("set-point", str(exc)))  # the app notifies and logs it
            return
        echo = Echo(kind, key, value, rate if kind is Entry.TORQUER_BIAS else 0.0)
        self._pending[box.id] = echo
        box.value = echo.text
        box.cursor_position = len(echo.text)
        self.message(f"{echo.words}: Enter again to send it (edit the box to cancel)", True)

    def on_input_changed(self, event: Input.Changed) -> None:
        echo = self._pending.get(event.input.id or "")
        if echo is not None and event.value != echo.text:  # edited: the echo is not what it says
            del self._pending[event.input.id or ""]
            self.message("not sent: type the value and Enter to check it again", True)

    def cancel_pending(self, why: str, boxes: list[str] | None = None) -> None:
        """Cancel the echoes not yet sent (all, or those of ``boxes``) and empty their boxes."""
        gone = [b for b in self._pending if boxes is None or b in boxes]
        for b in gone:
            del self._pending[b]
            self.query_one(f"#{b}", Input).value = ""
        if gone:
            self.message(f"not sent ({why}): type it again", False)

    def on_checkbox_changed(self, event: Checkbox.Changed) -> None:
        event.stop()
        if event.checkbox.id and event.checkbox.id.startswith("cage-"):
            self.post_message(self.Request(Entry.CAGING, event.checkbox.id[5:], bool(event.value)))

    def show(self, snap: Snapshot) -> None:
        key = state_key(snap)
        if key == self._shown:
            return
        before, self._shown = self._shown, key
        if before and self._pending:
            # the rig moved under an echo not yet sent: its value was checked against another state
            if before[3:] != key[3:]:  # a safe state, an abort, a procedure, a mode change
                self.cancel_pending(f"the console is now {snap.phase}, mode {key[4]}")
            else:
                moved = [name for name, v in snap.readback.items() if before[0].get(name) != v]
                self.cancel_pending("its read-back changed", [n.replace(" ", "-") for n in moved])
        if self._message_state is not None and self._message_state != key:
            self.message("", True)  # it described a state the rig has left
        for name, v in snap.readback.items():
            kind, ch = name.split(" ")
            text = f"{v:+.4f} V"
            if kind == "torq" and ch in snap.slewing:
                text += f"  slewing -> {snap.slewing[ch]:+.4f}"
            w = self._back.get(name)
            if w is not None:
                w.update(text, layout=False)
        for c, inhibited in snap.caging.items():
            box = self._boxes[c]
            if box.value != inhibited:
                with box.prevent(Checkbox.Changed):  # a read-back is not an operator's request
                    box.value = inhibited
            if str(box.label) != (words := caging_label(c, inhibited)):
                box.label = words


def state_key(snap: Snapshot) -> tuple:
    """What the panel shows of a snapshot, and what a set-point was checked in: read-backs,
    slews, caging switches, the console's phase, the mode in force."""
    return (
        snap.readback,
        snap.slewing,
        snap.caging,
        snap.phase,
        snap.relay.mode if snap.relay else None,
    )


@dataclass(frozen=True)
class Echo:
    """A checked set-point waiting for Enter on its echo."""

    kind: Entry
    key: str
    value: float
    slew: float = 0.0

    @property
    def text(self) -> str:
        return f"{self.value:+.10g}"  # every digit that will be sent

    @property
    def words(self) -> str:
        what = {
            Entry.TORQUER_BIAS: f"torquer bias {self.key}",
            Entry.COMMAND_TORQUE: f"command torque {self.key}",
            Entry.AC_BIAS: f"autocollimator bias {self.key}",
        }[self.kind]
        return (
            what
            + f" {self.text} V"
            + (f" at {self.slew:g} V/s" if self.kind is Entry.TORQUER_BIAS else "")
        )


def caging_label(channel: str, inhibited: bool) -> str:
    """A caging switch in words: "auto" (the relay driver cages by mode) or "inhibited"."""
    return f"{channel} {'inhibited' if inhibited else 'auto'}"
