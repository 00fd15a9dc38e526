"""Issue 37 item 6/7, acceptance C: after every abort path each panel says what the rig read
back, never what was typed or what was true a minute ago; a burst of keys lands in order.

``panels_show_the_read_back`` compares the header, the modes panel, the alarm lamp and the
set-point rows with the rig thread's read-back and with the emulated nodes' own registers.
"""

from __future__ import annotations

import re

from textual import events
from textual.widgets import Checkbox, Input, Static

from console.app import ConsoleApp
from drivers.relay import MODES
from drivers.rig_datasheet import AXES, GYRO_CHANNELS

from .conftest import (
    COLD,
    WARM,
    nodes_safe,
    outcome,
    rig_ready,
    run_async,
    start_procedure,
    wait_for,
)

SETPOINT_BOXES = (
    *(f"torq-{c}" for c in GYRO_CHANNELS),
    *(f"{k}-{a}" for k in ("gc", "vtd") for a in AXES),
)


def text_of(app, selector: str) -> str:
    return str(app.query_one(selector, Static).render())


def panels_show_the_read_back(app) -> list[str]:
    """Every disagreement between a panel and the read-back state (empty: none)."""
    snap = app.worker_.state.get()
    st = snap.relay
    wrong = []
    header, now = text_of(app, "#status"), text_of(app, "#mode-now")
    if f"MODE {st.mode}" not in header or MODES[st.mode] not in header:
        wrong.append(f"header {header!r} is not mode {st.mode}")
    if f"MODE {st.mode}" not in now:
        wrong.append(f"modes panel {now!r} is not mode {st.mode}")
    last = text_of(app, "#mode-last")
    for m in re.findall(r"mode (\d) \([^)]*\) in force", last):
        if int(m) != st.mode:
            wrong.append(f"modes panel says {last!r} in mode {st.mode}")
    alarm = text_of(app, "#mode-alarm")
    if ("ALARM" in alarm) != bool(snap.alarm or snap.fault):
        wrong.append(f"alarm lamp {alarm!r} with alarm {snap.alarm!r}")
    if "wheels at" in alarm:
        shown = int(re.search(r"wheels at (\d+) %", alarm).group(1))
        if abs(shown - 100 * st.spin_fraction) > 2:
            wrong.append(
                f"alarm says wheels at {shown} % with the wheels at {100 * st.spin_fraction:.0f} %"
            )
    for name, v in snap.readback.items():
        back = text_of(app, f"#back-{name.replace(' ', '-')}")
        if not back.startswith(f"{v:+.4f} V"):
            wrong.append(f"read-back column {name} shows {back!r}, read back {v:+.4f}")
    for box in SETPOINT_BOXES:
        if typed := app.query_one(f"#{box}", Input).value:
            wrong.append(f"set-point box {box} still holds {typed!r}")
    for c, inhibited in snap.caging.items():
        cb = app.query_one(f"#cage-{c}", Checkbox)
        if cb.value != inhibited or str(cb.label) != f"{c} {'inhibited' if inhibited else 'auto'}":
            wrong.append(f"caging switch {c} shows {cb.label} with inhibit read back {inhibited}")
    msg = text_of(app, "#sp-message")
    for c in re.findall(r"caging (\w+) inhibited", msg):
        if not snap.caging.get(c):
            wrong.append(f"set-point message {msg!r} with caging {c} released")
    return wrong


async def settle(pilot) -> None:
    """The read-back polled once more (status 0.5 s, outputs 1 s) and drawn."""
    app = pilot.app
    t0 = app.worker_.state.get().rig_time_s
    await wait_for(
        pilot, lambda: app.worker_.state.get().rig_time_s > t0 + 1.2, what="a fresh read-back"
    )
    await pilot.pause(0.3)


async def dirty_the_panels(pilot, *, inhibit: bool = True) -> None:
    """Biases and a caging inhibit set, an echo not sent, "mode 3 in force". (A procedure
    needs the gyros caged: before one, ``inhibit=False``.)"""
    app = pilot.app
    state = app.worker_.state
    await pilot.press("f3")
    app.query_one("#slew", Input).value = "5"
    app.query_one("#torq-X", Input).focus()
    await pilot.press(*"0.25", "enter", "enter")
    app.query_one("#gc-X", Input).focus()
    await pilot.press(*"0.1", "enter", "enter")
    await wait_for(
        pilot,
        lambda: (
            abs(state.get().readback.get("torq X", 0) - 0.25) < 1e-3
            and abs(state.get().readback.get("gc X", 0) - 0.1) < 1e-3
            and not state.get().slewing
        ),
        what="the biases set",
    )
    if inhibit:
        app.query_one("#cage-Y", Checkbox).focus()
        await pilot.press("space")
        await wait_for(
            pilot, lambda: state.get().caging.get("Y") is True, what="caging Y inhibited"
        )
        await pilot.pause(0.3)
        assert "caging Y inhibited" in text_of(app, "#sp-message")
    app.query_one("#torq-Y", Input).focus()
    await pilot.press(*"0.1", "enter")  # echoed, never sent
    assert app.query_one("#torq-Y", Input).value == "+0.1"
    await pilot.press("f2", "h", "3", "r")
    await wait_for(
        pilot, lambda: (o := outcome(app, "release")) is not None and o.ok, what="mode 3 in force"
    )
    await pilot.pause(0.3)
    assert "mode 3 (autocollimator control) in force" in text_of(app, "#mode-last")


async def abort_a_stopwatch(pilot, *keys: str) -> None:
    """Dirty panels, a stopwatch into its second step, then ``keys`` abort it; until it ends."""
    app = pilot.app
    await dirty_the_panels(pilot, inhibit=False)
    await start_procedure(pilot, "stopwatch")
    await wait_for(
        pilot,
        lambda: (p := app.worker_.state.get().procedure) is not None and p.index >= 1,
        what="the procedure's second step",
    )
    await pilot.press(*keys)
    await wait_for(pilot, lambda: app.last_summary is not None, what="the procedure to end")


@run_async
async def test_after_an_f8_abort_every_panel_shows_the_read_back_state(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(100, 40)) as pilot:
        await rig_ready(pilot)
        await abort_a_stopwatch(pilot, "f8")
        assert app.last_summary.verdict == "aborted"
        await settle(pilot)
        assert nodes_safe(app.worker_.rig.emulator)
        assert app.worker_.state.get().relay.mode == 1
        assert panels_show_the_read_back(app) == []
        assert text_of(app, "#mode-last") == ""  # "mode 3 in force" went with mode 3
    # the run's log beside its file, as fbs run writes it: this program's records, none of canopen's INFO
    log = (out_dir / "stopwatch.log").read_text()
    assert "procedure stopwatch starting" in log and "stopwatch aborted" in log
    assert not re.search(r" INFO (?!(fbs|drivers|simhw|daq|procedures|console)\b)", log)


@run_async
async def test_after_the_safe_key_every_panel_shows_the_read_back_state(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(100, 40)) as pilot:
        await rig_ready(pilot)
        await dirty_the_panels(pilot)
        await pilot.press("s")
        await wait_for(pilot, lambda: outcome(app, "safe state") is not None, what="the safe state")
        await settle(pilot)
        assert nodes_safe(app.worker_.rig.emulator)
        assert panels_show_the_read_back(app) == []
        assert "safe state" in text_of(app, "#mode-last")  # said while it holds


@run_async
async def test_the_safe_key_during_a_procedure_aborts_it_and_the_panels_follow(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(100, 40)) as pilot:
        await rig_ready(pilot)
        await abort_a_stopwatch(pilot, "f2", "s")
        await settle(pilot)
        assert panels_show_the_read_back(app) == []


@run_async
async def test_a_refused_release_alarm_follows_the_wheels_and_goes_out_with_its_cause(
    out_dir, tmp_path
):
    config = tmp_path / "fast.toml"
    # The wheels reach speed in seconds of rig time, and the rig's virtual time runs on while
    # the keys are pressed (3 s of it on an idle box, 6 s on a loaded one): the refusal must
    # land well before the wheels are at speed, so they take 20 s.
    config.write_text("[gyros]\nspin_up_time_s = 20.0\n")
    app = ConsoleApp(COLD + f"&config={config}", out_dir=out_dir)
    async with app.run_test(size=(100, 40)) as pilot:
        await rig_ready(pilot)
        state = app.worker_.state
        await pilot.press("f2", "h", "2", "r")
        await wait_for(pilot, lambda: state.get().relay.mode == 2, what="mode 2")
        await pilot.press("h", "4", "r")  # refused: not at speed, not caged
        first_alarm: list[str] = []  # as the lamp said it first, not after the wheels moved on

        def refused() -> bool:
            alarm = state.get().alarm
            if outcome(app, "release") is None or not alarm:
                return False
            first_alarm.append(alarm)
            return True

        await wait_for(pilot, refused, what="refusal")
        assert "gyros not at speed" in outcome(app, "release").text
        assert "gyros not at speed" in first_alarm[0]
        await wait_for(
            pilot, lambda: all(state.get().relay.at_speed.values()), what="the wheels at speed"
        )
        await settle(pilot)
        alarm = text_of(app, "#mode-alarm")
        assert "ALARM" in alarm and "not caged" in alarm  # still refused, for what is still so
        assert "not at speed" not in alarm  # not for what was so a minute ago
        assert panels_show_the_read_back(app) == []
        await pilot.press("s")  # the selection goes: so does the lamp
        await wait_for(pilot, lambda: outcome(app, "safe state") is not None, what="the safe state")
        await settle(pilot)
        assert "ALARM" not in text_of(app, "#mode-alarm") and panels_show_the_read_back(app) == []


@run_async
async def test_a_burst_of_keys_with_backspace_sends_what_was_typed(out_dir):
    """Keys queued faster than the console handles them (a terminal's burst: they are posted,
    not awaited one by one as Pilot's ``press`` does). Textual's own Input leaves "0.1" of
    "0.12", Backspace, Backspace, "3"; and nothing is sent before Enter on the echo."""
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(100, 40)) as pilot:
        await rig_ready(pilot)
        await pilot.press("f3")
        app.query_one("#slew", Input).value = "5"
        box = app.query_one("#torq-X", Input)
        box.focus()
        await pilot.pause()
        for key, char in [
            ("0", "0"),
            ("full_stop", "."),
            ("1", "1"),
            ("2", "2"),
            ("backspace", "\x7f"),
            ("backspace", "\x7f"),
            ("3", "3"),
            ("enter", "\r"),
        ]:
            app.post_message(events.Key(key, char))
        await pilot.pause(0.5)
        assert box.value == "+0.3"  # the value that will be sent
        assert outcome(app, "torquer bias X") is None  # not yet
        await pilot.press("enter")
        await wait_for(
            pilot,
            lambda: (
                abs(app.worker_.state.get().readback.get("torq X", 0) - 0.3) < 1e-3
                and not app.worker_.state.get().slewing
            ),
            what="the bias at 0.3 V",
        )
        # an edited echo is cancelled: Enter checks it again and echoes it, it does not send
        n = len(app.outcomes)
        await pilot.press(*"0.2", "enter", "backspace", "5", "enter")
        await pilot.pause(0.3)
        assert box.value == "+0.5" and len(app.outcomes) == n
