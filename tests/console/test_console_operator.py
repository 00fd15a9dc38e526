"""Issue 20, acceptance A: the console as a new operator meets it (Textual Pilot against the
loopback rig in virtual time). Nothing here waits on a wall-clock deadline: the rig's own time
is the yardstick, and the time-outs are only guards against a hang."""

from __future__ import annotations

import io
import re
import threading

import pytest
from rich.console import Console
from textual.widgets import Checkbox, Input, RichLog, Static

from console.app import PANELS, ConsoleApp, exit_line
from console.keyhelp import GLOBAL_HELP, HelpScreen, help_keys
from console.meterdata import MeterSnapshot
from console.quitscreen import QuitScreen
from daq.reader import RunFile

from .conftest import COLD, WARM, outcome, rig_ready, run_async, start_procedure, wait_for

pytestmark = pytest.mark.slow

#: how far (rig time) a panel may lag the rig (acceptance A)
LAG_S = 1.0


def text_of(app, selector: str) -> str:
    return str(app.query_one(selector, Static).render())


def record_updates(worker) -> list[tuple[frozenset[str], object]]:
    """Every state the rig thread publishes, with the names it changed."""
    published: list[tuple[frozenset[str], object]] = []
    update = worker.state.update

    def recorded(**changes):
        snap = update(**changes)
        published.append((frozenset(changes), snap))
        return snap

    worker.state.update = recorded
    return published


class Checkpoints:
    """Stops the rig thread at chosen moments until the console shows what the rig is in.

    The rig runs in virtual time, far faster than a screen refreshes; held at a moment of rig
    time, the rig cannot run ahead, so "the panel shows it" means "within no rig time at all".
    ``hold`` runs on the rig thread; ``serve`` on the UI's side, between pilot pauses."""

    def __init__(self) -> None:
        self.pending: tuple[str, object] | None = None
        self.passed: list[str] = []
        self.failed: list[str] = []
        self._done = threading.Event()

    def hold(self, what: str, shown) -> None:
        self._done.clear()
        self.pending = (what, shown)
        if not self._done.wait(60.0):  # a hang guard only
            self.failed.append(what)
        self.pending = None

    def serve(self) -> None:
        if self.pending is not None and self.pending[1]():
            self.passed.append(self.pending[0])
            self._done.set()


@run_async
async def test_the_rig_is_polled_and_shown_while_a_procedure_runs(out_dir):
    app = ConsoleApp(COLD, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        worker, rig = app.worker_, app.worker_.rig
        events: list[tuple[float, str, str]] = []
        cp = Checkpoints()
        mode_2_at: list[float] = []  # rig time of the spin-up's start

        def on_event(t: float, kind: str, text: str) -> None:  # after the console's own listener
            events.append((t, kind, text))
            if text == "mode 2":
                mode_2_at.append(t)
            if kind == "mode":
                cp.hold(
                    text,
                    lambda: (
                        f"MODE {text[5:]} " in text_of(app, "#status")
                        and f"MODE {text[5:]}" in text_of(app, "#mode-now")
                    ),
                )
            elif text == "caging inhibit X = on" and "caging X on" not in cp.passed:
                cp.hold("caging X on", lambda: app.query_one("#cage-X", Checkbox).value is True)
            elif (
                text.startswith("torquer bias X = ")
                and (v := float(text.split()[4])) != 0
                and len(cp.passed) < 6
            ):
                cp.hold(
                    f"bias X {v:+.4f}",
                    lambda: text_of(app, "#back-torq-X").startswith(f"{v:+.4f} V"),
                )

        rig.subscribe(on_event)
        poll = rig.adc.after_block

        def after_block() -> None:  # the wheels in mid spin-up
            poll()
            # counted from mode 2, not from the rig's start: the idle rig's time runs on while
            # a fresh worker imports the catalogue, and mode 2 may come late on a loaded box
            if mode_2_at and rig.now() > mode_2_at[0] + 20 and "wheels" not in cp.passed:
                wheels = rig.relays.status().spin_fraction
                cp.hold(
                    "wheels", lambda: f"wheels {100 * wheels:.0f} %" in text_of(app, "#mode-gyros")
                )

        rig.adc.after_block = after_block
        published = record_updates(worker)
        await start_procedure(pilot, "stopwatch", 'channels=["X"] repetitions=1')

        def progress() -> bool:
            cp.serve()
            return len(cp.passed) >= 6 or bool(cp.failed)

        # cold: spin-up in mode 2, mode 3, caged; then step 2 inhibits caging on X and biases it
        await wait_for(pilot, progress, what="the procedure to open the X loop")
        rig.unsubscribe(on_event)
        await pilot.press("f8")
        await wait_for(pilot, lambda: app.last_summary is not None, what="the abort")
        assert app.last_summary.verdict == "aborted"
    assert not cp.failed and cp.passed[:4] == ["mode 2", "wheels", "mode 3", "caging X on"], (
        cp.passed
    )

    during = [(keys, s) for keys, s in published if s.phase == "procedure"]
    # the relay status (mode, wheels, caged flags) polled at least once a second of rig time
    polls = [s.rig_time_s for keys, s in during if "relay" in keys]
    assert (
        len(polls) > 200
        and max(b - a for a, b in zip(polls, polls[1:], strict=False)) <= LAG_S + 1e-6
    )
    wheels = [s.relay.spin_fraction for keys, s in during if "relay" in keys]
    assert wheels[0] < 0.5 and wheels[-1] == pytest.approx(1.0)

    # each command the procedure gave, read back within LAG_S of rig time
    def shown(t: float, ok) -> bool:
        return any(t <= s.rig_time_s <= t + LAG_S and ok(s) for _, s in during)

    modes = [(t, int(text.split()[1])) for t, kind, text in events if kind == "mode"]
    assert [m for _, m in modes][:2] == [2, 3]
    for t, mode in modes:
        assert shown(t, lambda s, mode=mode: s.relay.mode == mode), (
            f"mode {mode} at {t:.2f} s not shown"
        )
    biases = [
        (t, float(text.split("= ")[1].split()[0]))
        for t, kind, text in events
        if kind == "setpoint" and text.startswith("torquer bias X")
    ]
    cages = [
        (t, text.endswith("on"))
        for t, kind, text in events
        if kind == "setpoint" and text.startswith("caging inhibit X")
    ]
    assert any(v != 0 for _, v in biases) and any(on for _, on in cages)
    for t, v in biases:
        assert shown(t, lambda s, v=v: abs(s.readback["torq X"] - v) < 1e-5), (
            f"bias {v} at {t:.2f} s not shown"
        )
    for t, on in cages:
        assert shown(t, lambda s, on=on: s.caging["X"] is on), f"caging {on} at {t:.2f} s not shown"


def rendered(renderable, width: int = 76) -> str:
    """What a rich renderable (a table) shows at ``width`` columns, as plain text."""
    console = Console(width=width, file=io.StringIO(), color_system=None)
    with console.capture() as out:
        console.print(renderable)
    return out.get()


def screen_text(app) -> str:
    return "\n".join(str(w.render()) for w in app.screen.query(Static))


@run_async
async def test_quit_while_recording_asks_and_declining_keeps_recording(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        await pilot.press("f4", "f7")
        state = app.worker_.state
        await wait_for(
            pilot,
            lambda: (r := state.get().recording) is not None and r.samples > 200,
            what="recording",
        )
        path = state.get().recording.path
        await pilot.press("q")
        await wait_for(pilot, lambda: isinstance(app.screen, QuitScreen), what="the question")
        asked = screen_text(app)
        assert f"the recording {path}" in asked and "safe state" in asked and "y quit" in asked
        await pilot.press("q")  # a second q is not an answer
        await pilot.press("n")
        await wait_for(
            pilot, lambda: not isinstance(app.screen, QuitScreen), what="the question to close"
        )
        n = state.get().recording.samples
        await wait_for(pilot, lambda: state.get().recording.samples > n + 200, what="more samples")
        assert state.get().phase == "recording" and not app.worker_.stopped.is_set()
        await pilot.press("ctrl+q")  # the other quit key asks too
        await wait_for(pilot, lambda: isinstance(app.screen, QuitScreen), what="the question again")
        await pilot.press("escape")
        await wait_for(
            pilot, lambda: not isinstance(app.screen, QuitScreen), what="the question to close"
        )
        assert state.get().phase == "recording"
        await pilot.press("q")
        await wait_for(
            pilot, lambda: isinstance(app.screen, QuitScreen), what="the question a third time"
        )
        await pilot.press("y")
        await wait_for(pilot, lambda: app.worker_.stopped.is_set(), what="the rig closed")
    status = "aborted: ConsoleClosed: the operator quit the console"
    with RunFile(path) as rf:
        assert rf.status == status
    line = exit_line(app.stopped)
    assert f"closed recording {path} ({status})" in line and "safe state: yes (read back)" in line


@run_async
async def test_quit_during_a_procedure_names_it_and_its_file(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        await start_procedure(pilot, "stopwatch")
        state = app.worker_.state
        await wait_for(
            pilot,
            lambda: (p := state.get().procedure) is not None and p.index >= 1,
            what="the procedure's second step",
        )
        await pilot.press("q")
        await wait_for(pilot, lambda: isinstance(app.screen, QuitScreen), what="the question")
        asked = screen_text(app)
        # step 2/5 or later: the rig's virtual time runs on while the key is handled
        assert re.search(r"the procedure stopwatch \(step [2-5]/5", asked), asked
        assert str(out_dir / "stopwatch.h5") in asked
        await pilot.press("n")
        await wait_for(
            pilot, lambda: not isinstance(app.screen, QuitScreen), what="the question to close"
        )
        assert state.get().phase == "procedure" and not state.get().procedure.aborting
        await pilot.press("q", "y")
        await wait_for(pilot, lambda: app.worker_.stopped.is_set(), what="the rig closed")
    assert app.last_summary.verdict == "aborted"
    assert f"closed procedure stopwatch's file {out_dir / 'stopwatch.h5'} (aborted: " in exit_line(
        app.stopped
    )


@run_async
async def test_quit_with_nothing_live_does_not_ask(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        await pilot.press("q")
        await wait_for(pilot, lambda: app.worker_.stopped.is_set(), what="the rig closed")
    assert exit_line(app.stopped) == (
        "fbs console: rig closed (the operator quit the console); safe state: yes (read back)"
    )


@run_async
async def test_question_mark_shows_every_key_of_the_panel(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        global_keys = {b.key for b in app.BINDINGS}
        assert global_keys <= set().union(*(help_keys(k) for k, _ in GLOBAL_HELP)) | {
            "question_mark"
        }
        for pid, title, key in PANELS:
            await pilot.press(key)
            panel = app.query_one(f"#{pid}-panel")
            await pilot.press("question_mark")
            await wait_for(
                pilot, lambda: isinstance(app.screen, HelpScreen), what=f"the help of {title}"
            )
            shown = rendered(app.screen.query_one("#help-keys", Static).content)
            assert f"Keys: {key.upper()} {title}" in screen_text(app)
            listed = set().union(*(help_keys(k) for k, _ in panel.KEY_HELP))
            for binding in vars(type(panel)).get(
                "BINDINGS", ()
            ):  # the panel's own keys (its footer)
                assert binding.key in listed, f"{title}: {binding.key} missing from the help"
            for k, does in (*panel.KEY_HELP, *GLOBAL_HELP):
                assert k in shown and does.split()[0] in shown
            await pilot.press("escape")
            await wait_for(
                pilot, lambda: not isinstance(app.screen, HelpScreen), what="the help to close"
            )
        # Tab moves within the panel: its keys keep working (F7 on Procedures after Tab, Tab)
        await pilot.press("f5", "tab", "tab", "tab")
        assert app.focused is not None and app.w_procedures in app.focused.ancestors_with_self


def log_text(app) -> str:
    """The event log as one line of text (an entry may wrap over several rows)."""
    return re.sub(
        r"\s+", " ", " ".join(str(line.text) for line in app.query_one("#event-log", RichLog).lines)
    )


@run_async
async def test_the_event_log_records_refusals_follows_and_collapses_slews(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        await pilot.press("f3")
        app.query_one("#slew", Input).value = "0.5"
        box = app.query_one("#torq-X", Input)
        box.focus()
        await pilot.press(*"20", "enter")  # refused here: out of range
        box.value = ""
        await pilot.press(*"0.5", "enter", "enter")  # a ramp of 1 s, a step a tick
        state = app.worker_.state
        await wait_for(
            pilot,
            lambda: (
                outcome(app, "torquer bias X") is not None
                and not state.get().slewing
                and abs(state.get().readback["torq X"] - 0.5) < 1e-3
            ),
            what="the ramp",
        )
        await pilot.press("f2", "h", "7")  # a disallowed mode: the alarm, and refused
        await wait_for(
            pilot, lambda: outcome(app, "select mode 7") is not None, what="mode 7 refused"
        )
        await pilot.press("f4")
        await wait_for(
            pilot, lambda: "mode 7 is not allowed" in log_text(app), what="the alarm in the log"
        )
        text = log_text(app)
        stamp = r"\d\d:\d\d:\d\d r +\d+\.\d\d s "  # wall clock, then rig time
        assert re.search(
            stamp + r"refused set-point: torquer bias \(V\) on gyro channel X 20\.0 is outside",
            text,
        )
        assert re.search(stamp + r"alarm mode 7 is not allowed", text)
        assert text.count("mode 7 is not allowed") == 1  # the refusal repeats the alarm: one line
        # the ramp: one line, not one a step
        assert "torquer bias X = " not in text
        ramp = re.findall(
            r"setpoint torquer bias X \+0\.0000 -> \+0\.5000 V at 0\.5 V/s in (\d+) step\(s\)", text
        )
        assert (
            len(ramp) == 1
            and int(ramp[0]) >= 2
            and re.search(r"read back \+0\.(49|50)\d\d V", text)
        )
        # the log follows its newest entry
        for i in range(40):
            app.note("console", f"note {i}")
        await wait_for(pilot, lambda: "note 39" in log_text(app), what="forty notes")
        await pilot.pause(0.2)
        log = app.query_one("#event-log", RichLog)
        assert (
            log.max_scroll_y > 0 and log.scroll_y == log.max_scroll_y
        )  # it follows the newest entry
        assert log.max_scroll_x == 0  # no horizontal scroll bar over it


@run_async
async def test_frozen_and_missing_values_say_why_and_caging_is_in_words(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir, live_meters=False)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        table = app.w_meters.query_one("#meter-table")
        app.show_meter_frame(
            MeterSnapshot(1, {"gyro_x": -10.0, "gyro_y": 0.01}, {"gyro_x": (-10.0,) * 10})
        )
        await pilot.pause(0.1)
        rows = {line.split()[0]: line for line in str(table.render()).splitlines()}
        assert (
            rows["gyro_x"].endswith("RAIL") and "RAIL" not in rows["gyro_y"]
        )  # at the rail: flagged
        assert "no reading" in rows["gyro_z"]  # no number: and why
        assert "PAUSED" not in str(table.render())
        await pilot.press("p")
        assert "PAUSED" in str(table.render()).splitlines()[0]  # the panel says it is frozen
        assert "before the pause" in text_of(app, "#chart-a .chart-title")
        await pilot.press("p")
        assert "PAUSED" not in str(table.render())
        # caging in words, and what engages it
        assert "caged: all" in text_of(app, "#mode-gyros")  # warm: mode 3, caged
        await pilot.press("f3")
        box = app.query_one("#cage-X", Checkbox)
        assert str(box.label) == "X auto"
        box.focus()
        await pilot.press("space")
        await wait_for(
            pilot,
            lambda: app.worker_.state.get().caging.get("X") is True,
            what="caging X inhibited",
        )
        await wait_for(pilot, lambda: str(box.label) == "X inhibited", what="the switch in words")
        await wait_for(
            pilot,
            lambda: (
                "inhibited on Set-points: X" in text_of(app, "#mode-gyros")
                or "caged: all" in text_of(app, "#mode-gyros")
            ),
            what="the modes panel",
        )


@run_async
async def test_an_expired_toast_is_painted_over(out_dir):
    """A terminal kept an expired toast's text over the panel (tmux, 80 s after): the console
    repaints the whole screen once a toast has gone."""
    app = ConsoleApp(WARM, out_dir=out_dir)
    repaints: list[int] = []
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        repaint = app._repaint_after_toast
        app._repaint_after_toast = lambda: (
            repaints.append(len(app.screen.query("Toast"))),
            repaint(),
        )
        app.notify("a short toast", timeout=0.3)
        await wait_for(pilot, lambda: bool(repaints), what="the repaint after the toast")
    assert repaints == [0]  # the toast had gone when the screen was repainted
