"""The set-point panel: caging-inhibit switches, torquer biases (with slew), autocollimator
biases and command torques, each with its range and the rig's read-back.

A typed value is checked here with the drivers' own rules (``limits.SetpointLimits``); a bad
entry is refused with the drivers' message, naming the value and the limit, and nothing goes
to the rig thread.
"""

from __future__ import annotations

from typing import ClassVar

from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Horizontal, VerticalScroll
from textual.message import Message
from textual.widgets import Checkbox, Input, Static

from console.keyhelp import PanelHelp
from console.limits import SLEW_DEFAULT_V_PER_S, SLEW_MAX_V_PER_S, SLEW_MIN_V_PER_S, Entry, typed_setpoint, typed_slew
from console.state import Snapshot
from drivers.calibration import AXES, GYRO_CHANNELS
from drivers.errors import SetpointRangeError
from drivers.setpoints import SetpointLimits


class SetpointPanel(VerticalScroll, can_focus=True):
    KEY_HELP: ClassVar[PanelHelp] = (
        ("Tab / shift+Tab", "the next / previous box"),
        ("Enter", "in a box: send the typed value (checked against its range first; a ramp for a torquer bias)"),
        ("Space", "on a caging switch: inhibit caging on that channel / release it (read back from the node)"),
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
        yield Static("  auto: the gyro cages by itself in mode 3; inhibited: its loop is held open",
                     id="sp-caging-note")
        yield Static("torquer bias (V)   set             range           read-back", classes="sp-head")
        for c in GYRO_CHANNELS:
            yield from self._row("torq", c, f"  gyro {c}")
        with Horizontal(classes="sp-row"):
            yield Static("  slew (V/s)", classes="sp-label")
            yield Input(f"{SLEW_DEFAULT_V_PER_S:g}", id="slew", compact=True, classes="sp-input")
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
            yield Input(placeholder="volts", id=f"{kind}-{key}", compact=True, classes="sp-input")
            yield Static("", id=f"range-{kind}-{key}", classes="sp-range")
            yield Static("—", id=f"back-{kind}-{key}", classes="sp-back")

    def set_limits(self, limits: SetpointLimits) -> None:
        self.limits = limits
        for c in GYRO_CHANNELS:
            self.query_one(f"#range-torq-{c}", Static).update(f"+-{limits.torquer_limit_V(c):.4g} V")
        for a in AXES:
            for kind in ("gc", "vtd"):
                self.query_one(f"#range-{kind}-{a}", Static).update(f"+-{limits.calibration.dac_range_V:g} V")

    def message(self, text: str, ok: bool) -> None:
        self.query_one("#sp-message", Static).update(Text(text, style="green" if ok else "bold red"))

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        if self.limits is None or event.input.id is None:
            self.message("the rig is not open yet", False)
            return
        prefix, _, key = event.input.id.partition("-")
        kind = Entry(prefix)
        try:
            if kind is Entry.SLEW:
                rate = typed_slew(event.value)
                self.message(f"torquer bias slew {rate:g} V/s", True)
                return
            rate = typed_slew(self.query_one("#slew", Input).value)
            value = typed_setpoint(self.limits, kind, key, event.value)
        except SetpointRangeError as exc:  # refused here: nothing goes to the rig
            self.message(f"refused: {exc}", False)
            self.post_message(self.Refused("set-point", str(exc)))   # the app notifies and logs it
            return
        self.post_message(self.Request(kind, key, value, rate))

    def on_checkbox_changed(self, event: Checkbox.Changed) -> None:
        event.stop()
        if event.checkbox.id and event.checkbox.id.startswith("cage-"):
            self.post_message(self.Request(Entry.CAGING, event.checkbox.id[5:], bool(event.value)))

    def show(self, snap: Snapshot) -> None:
        key = (snap.readback, snap.slewing, snap.caging)
        if key == self._shown:
            return
        self._shown = key
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


def caging_label(channel: str, inhibited: bool) -> str:
    """A caging switch in words: "auto" (the relay driver cages by mode) or "inhibited"."""
    return f"{channel} {'inhibited' if inhibited else 'auto'}"
