"""Issue 7, acceptance A: Textual Pilot drives the console against the loopback rig (the real
drivers, bytes over a pty and a virtual CAN bus)."""

from __future__ import annotations

import re

import pytest
from textual.widgets import Input, Static

from console.app import ConsoleApp
from daq.reader import RunFile

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

pytestmark = pytest.mark.slow


def text_of(app, selector: str) -> str:
    return str(app.query_one(selector, Static).render())


@run_async
async def test_mode_3_by_hold_select_release(out_dir):
    app = ConsoleApp(COLD, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        assert app.worker_.state.get().relay.mode == 1
        await pilot.press("f2", "h")
        await wait_for(pilot, lambda: app.worker_.state.get().relay.held, what="the hold")
        await pilot.press("3")
        await wait_for(
            pilot, lambda: app.worker_.state.get().relay.selected == 3, what="mode 3 selected"
        )
        assert app.worker_.state.get().relay.mode == 1  # nothing changes before release
        await pilot.press("r")
        await wait_for(
            pilot, lambda: app.worker_.state.get().relay.mode == 3, what="mode 3 in force"
        )
        st = app.worker_.state.get().relay
        assert not st.held and st.mode == 3
        assert "MODE 3" in text_of(app, "#mode-now") and "MODE 3" in text_of(app, "#status")
        assert "mode 3 (autocollimator control) in force" in outcome(app, "release").text
        emulator = app.worker_.rig.emulator
        assert emulator.nodes.nodes["relay"].mode == 3  # the relay node itself switched
    assert nodes_safe(emulator)  # quitting left the rig safe


@run_async
async def test_disallowed_mode_and_interlock_light_the_alarm(out_dir):
    app = ConsoleApp(COLD, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        assert "alarm" in text_of(app, "#mode-alarm") and "ALARM" not in text_of(app, "#mode-alarm")
        await pilot.press("f2", "h", "7")
        await wait_for(pilot, lambda: outcome(app, "select mode 7") is not None, what="select 7")
        await pilot.pause(0.2)
        alarm = text_of(app, "#mode-alarm")
        assert "ALARM" in alarm and "mode 7 is not allowed" in alarm
        assert "ALARM" in text_of(app, "#status")
        assert app.worker_.state.get().relay.mode == 1  # the rig stays in its mode
        # an interlock refusal shows its reason: mode 4 needs the gyros at speed and caged
        await pilot.press("4", "r")
        await wait_for(pilot, lambda: outcome(app, "release") is not None, what="release")
        refused = outcome(app, "release")
        assert (
            not refused.ok and "mode 4 refused" in refused.text and "not at speed" in refused.text
        )
        await pilot.pause(0.2)
        alarm = text_of(app, "#mode-alarm")
        assert "ALARM" in alarm and "gyros not at speed" in alarm
        assert app.worker_.state.get().relay.mode == 1
        # a good mode change puts the lamp out
        await pilot.press("h", "2", "r")
        await wait_for(pilot, lambda: app.worker_.state.get().relay.mode == 2, what="mode 2")
        await pilot.pause(0.2)
        assert "ALARM" not in text_of(app, "#mode-alarm")


@run_async
async def test_torquer_bias_slews_to_the_read_back_and_bad_entries_are_refused(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        await pilot.press("f3")
        assert "+-8.077 V" in text_of(app, "#range-torq-X")
        app.query_one("#slew", Input).value = "2"
        box = app.query_one("#torq-X", Input)
        box.focus()
        await pilot.press(*"0.25", "enter")  # checked and echoed, not sent
        await pilot.pause(0.2)
        assert box.value == "+0.25" and outcome(app, "torquer bias X") is None
        assert "Enter again to send" in text_of(app, "#sp-message")
        await pilot.press("enter")  # Enter on the echo sends it
        await wait_for(
            pilot, lambda: outcome(app, "torquer bias X") is not None, what="the bias command"
        )
        assert box.value == ""  # the row shows the read-back only
        assert "slewing +0.0000 -> +0.2500 V at 2 V/s" in outcome(app, "torquer bias X").text
        # the ramp: the bias passes through intermediate values, then the read-back shows the target
        await wait_for(
            pilot,
            lambda: (
                abs(app.worker_.state.get().readback.get("torq X", 0) - 0.25) < 1e-3
                and not app.worker_.state.get().slewing
            ),
            what="the bias at 0.25 V",
        )
        await pilot.pause(0.2)
        back = text_of(app, "#back-torq-X")
        assert back.endswith(" V") and float(back.split()[0]) == pytest.approx(
            0.25, abs=3.1e-4
        )  # one DAC LSB
        emulator = app.worker_.rig.emulator
        assert emulator.nodes.nodes["torquer"].values["X"] != 0
        n_before = len(app.outcomes)
        # beyond the 3.5 x earth-rate limit: refused on the UI thread, nothing goes to the rig
        box.value = ""
        await pilot.press(*"20", "enter")
        await pilot.pause(0.3)
        msg = text_of(app, "#sp-message")
        assert msg.startswith("refused: torquer bias (V) on gyro channel X 20.0")
        assert "outside +-8.07671" in msg and "nothing was sent" in msg
        box.value = ""
        await pilot.press(*"abc", "enter")
        await pilot.pause(0.3)
        assert "is not a number" in text_of(app, "#sp-message")
        assert len(app.outcomes) == n_before  # no command reached the rig thread
        assert abs(app.worker_.state.get().readback["torq X"] - 0.25) < 1e-3
    assert nodes_safe(emulator)  # quit: biases back to zero


@run_async
async def test_record_start_stop_then_spectra(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        await pilot.press("f4")
        app.query_one("#rec-path", Input).value = str(out_dir / "bench.h5")
        app.query_one("#rec-rate", Input).value = "500"
        app.query_one("#rec-channels", Input).value = "gyro_x,gyro_y,torq_x"
        await pilot.press("f7")
        await wait_for(
            pilot, lambda: app.worker_.state.get().phase == "recording", what="recording"
        )
        await wait_for(
            pilot, lambda: app.worker_.state.get().recording.samples >= 1500, what="3 s of samples"
        )
        status = text_of(app, "#rec-status")
        assert "REC" in status and "bench.h5" in status and "gaps 0" in status
        assert "REC" in text_of(app, "#status")
        await pilot.press("f8")
        await wait_for(
            pilot, lambda: app.worker_.state.get().phase == "ready", what="recording stopped"
        )
        info = app.worker_.state.get().recording
        assert info.status == "complete" and info.samples >= 1500
        await pilot.pause(0.2)
        assert "complete" in text_of(app, "#rec-status")
        with RunFile(out_dir / "bench.h5") as rf:
            assert rf.status == "complete" and rf.n_samples == info.samples and rf.rate_hz == 500
            assert rf.channels == ["gyro_x", "gyro_y", "torq_x"] or list(rf.channels) == [
                "gyro_x",
                "gyro_y",
                "torq_x",
            ]
        # the spectra view of the last recording
        await pilot.press("f6", "f7")
        await wait_for(pilot, lambda: app.w_spectra.view is not None, what="the spectra")
        view = app.w_spectra.view
        assert view.path == out_dir / "bench.h5" and set(view.psd) == {"gyro_x", "gyro_y"}
        assert len(view.coherence) == len(view.f_hz) > 50 and all(
            0 <= c <= 1 for c in view.coherence
        )
        assert "gyro_x gyro_y" in text_of(app, "#spec-t0") and "the last recording" in text_of(
            app, "#spec-info"
        )


@run_async
async def test_stopwatch_runs_to_its_results(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        await start_procedure(pilot, "stopwatch", 'channels=["X"] repetitions=1')
        await wait_for(pilot, lambda: app.last_summary is not None, what="the procedure to end")
        s = app.last_summary
        assert (
            s.status == "complete"
            and s.verdict in ("pass", "fail")
            and s.file == out_dir / "stopwatch.h5"
        )
        # one repetition on the data sheet's K_TO: measured, shown, but not a resolved figure
        kg = next(m for m in s.measurements if m.name.startswith("K_g X (stopwatch"))
        assert kg.value == pytest.approx(6.03, rel=0.1)
        assert (
            s.values["K_g_mV_per_urad"]["X"] is None
            and s.values["resolved"]["K_g_mV_per_urad"]["X"] is False
        )
        await pilot.pause(0.2)
        result = text_of(app, "#proc-result")
        assert s.verdict.upper() in result and str(s.file) in result and "K_g" in result
        assert app.w_spectra.last_file == s.file  # the spectra view offers it next, saying whose
        assert (
            app.query_one("#spec-path", Input).placeholder
            == f"blank: {s.file} (the stopwatch run's file)"
        )
        log_text = "\n".join(str(line.text) for line in app.query_one("#proc-log").lines)
        assert "stopwatch: step 2/2: channel X" in log_text  # the live log showed the run


@run_async
async def test_stopwatch_aborted_leaves_the_rig_safe_and_the_file_aborted(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        await start_procedure(pilot, "stopwatch")  # all four channels: minutes of rig time
        await wait_for(
            pilot,
            lambda: (p := app.worker_.state.get().procedure) is not None and p.index >= 1,
            what="the procedure's second step",
        )
        # other commands are refused while the procedure owns the rig
        await pilot.press("f2", "h", "f5")
        assert outcome(app, "hold") is None
        await pilot.pause(0.1)
        assert re.search(r"step [2-5]/5 channel (X|Y|Z|XRD) · ", text_of(app, "#proc-step"))
        await pilot.press("f8")
        await wait_for(pilot, lambda: app.last_summary is not None, what="the procedure to end")
        s = app.last_summary
        assert (
            s.verdict == "aborted"
            and s.status == "aborted: ProcedureAborted: aborted by the operator"
        )
        assert s.file == out_dir / "stopwatch.h5" and s.file.exists()
        with RunFile(s.file) as rf:
            assert rf.status == s.status and rf.attrs["procedure"] == "stopwatch"
        await pilot.pause(0.2)
        result = text_of(app, "#proc-result")
        assert (
            "ABORTED" in result and str(s.file) in result and "aborted: ProcedureAborted" in result
        )
        emulator = app.worker_.rig.emulator
        assert nodes_safe(emulator)  # the abort left the rig safe
        await wait_for(
            pilot, lambda: app.worker_.state.get().relay.mode == 1, what="mode 1 read back"
        )
        assert app.worker_.busy is None  # the console takes commands again


@run_async
async def test_quit_while_recording_closes_the_file_and_leaves_the_rig_safe(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        app.worker_.set_torquer_bias("Y", 0.5, 5.0)
        await pilot.press("f4", "f7")
        await wait_for(
            pilot,
            lambda: (r := app.worker_.state.get().recording) is not None and r.samples > 200,
            what="recording",
        )
        emulator = app.worker_.rig.emulator
        path = app.worker_.state.get().recording.path
        assert path == out_dir / "recording.h5"  # the default name
        await pilot.press("q")
        await wait_for(
            pilot, lambda: app.screen.__class__.__name__ == "QuitScreen", what="the question"
        )
        await pilot.press("y")  # issue 20: a live recording asks first
        await wait_for(pilot, lambda: app.worker_.stopped.is_set(), what="the rig closed")
    assert nodes_safe(emulator)
    with RunFile(path) as rf:
        assert rf.status == "aborted: ConsoleClosed: the operator quit the console"
        assert any(e.kind == "safe" for e in rf.events)


def test_the_console_goes_safe_through_the_drivers_one_guard(out_dir, go_safe_calls):
    """Quitting while recording: the rig thread's ``drivers.safety`` guard drives the rig safe
    (before the file closes, so the file holds it), then the rig is closed."""
    test_quit_while_recording_closes_the_file_and_leaves_the_rig_safe(out_dir)
    assert go_safe_calls == ["the console aborted (ConsoleClosed: the operator quit the console)"]


@run_async
async def test_lost_device_aborts_the_recording_and_the_rig_goes_safe(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        await pilot.press("f4", "f7")
        await wait_for(
            pilot,
            lambda: (r := app.worker_.state.get().recording) is not None and r.samples > 200,
            what="recording",
        )
        path = app.worker_.state.get().recording.path
        emulator = app.worker_.rig.emulator
        emulator.inject("adc", "disconnect")  # the ADC's cable pulled
        await wait_for(pilot, lambda: app.worker_.state.get().phase == "fault", what="the fault")
        assert nodes_safe(emulator)
        with RunFile(path) as rf:
            assert rf.status.startswith("aborted: DeviceLost")
        await pilot.pause(0.2)
        assert "FAULT" in text_of(app, "#status")
        await pilot.press("f2")
        assert "device fault" in text_of(app, "#mode-alarm")
        await pilot.press("h")
        await pilot.pause(0.2)
        assert outcome(app, "hold") is None  # refused in the UI: the rig is faulted


@run_async
async def test_a_crash_in_the_ui_closes_the_recording_and_leaves_the_rig_safe(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    with pytest.raises(RuntimeError, match="boom"):
        async with app.run_test(size=(80, 24)) as pilot:
            await rig_ready(pilot)
            await pilot.press("f4", "f7")
            await wait_for(
                pilot,
                lambda: (r := app.worker_.state.get().recording) is not None and r.samples > 200,
                what="recording",
            )
            path = app.worker_.state.get().recording.path
            emulator = app.worker_.rig.emulator

            def boom() -> None:
                raise RuntimeError("boom")

            app.call_later(boom)
            await pilot.pause(0.5)
    assert app.worker_.stopped.is_set()
    assert nodes_safe(emulator)
    with RunFile(path) as rf:
        assert rf.status == "aborted: ConsoleClosed: the console crashed: RuntimeError: boom"


@run_async
async def test_manual_table_asks_the_operator_in_a_modal(out_dir):
    app = ConsoleApp(WARM + "&table=manual", out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        app.worker_.submit("table", lambda: str(app.worker_.rig.move_table(spindle_deg=90.0)))
        await wait_for(
            pilot, lambda: app.screen.__class__.__name__ == "OperatorScreen", what="the question"
        )
        shown = " ".join(str(w.render()) for w in app.screen.query(Static))
        assert "Set the rotary table to tilt" in shown and "spindle 90.0000 deg" in shown
        await pilot.press(*"90.5", "enter")
        await wait_for(pilot, lambda: outcome(app, "table") is not None, what="the move")
        assert "spindle_deg=90.5" in outcome(app, "table").text


@run_async
async def test_a_caging_lost_in_mode_4_is_an_alarm_the_console_shows(out_dir):
    """Issue 35 C: mode 4 in force, XRD's caging switch fails open at the rig (no command of the
    host's); the float runs off, the host's mode supervision alarms, the rig goes safe and the
    console says why."""
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        await pilot.press("f2", "h", "4", "r")
        await wait_for(
            pilot, lambda: app.worker_.state.get().relay.mode == 4, what="mode 4 in force"
        )
        emulator = app.worker_.rig.emulator
        emulator.submit(lambda sim: sim.set_caging_inhibit("XRD", True))
        await wait_for(
            pilot, lambda: app.worker_.state.get().phase == "fault", what="the supervision alarm"
        )
        assert (
            "mode 4 supervision" in app.worker_.state.get().fault
            and "gyro_xrd" in app.worker_.state.get().fault
        )
        assert nodes_safe(emulator) and emulator.sim.mode == 1
        await pilot.pause(0.2)
        assert "FAULT" in text_of(app, "#status")
        await pilot.press("f2")
        assert "device fault" in text_of(app, "#mode-alarm")
