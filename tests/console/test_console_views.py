"""Issue 20, the console's remaining items: results, parameters and file paths shown whole (and a
resume from the console), file names shown as written, one channel naming on every screen, a
notice for a terminal too small, the spin-up's time estimate and an interlock reason said once,
and the spectra drawn on log axes. Pilot tests against the loopback rig in virtual time; the
time-outs only guard against a hang."""

from __future__ import annotations

import dataclasses
import math
import threading
from pathlib import Path

import pytest
from textual.containers import VerticalScroll
from textual.widgets import Input, Static

from console.app import MIN_SIZE, ConsoleApp
from console.channels import meant, unknown_channels
from console.procedures import parse_run_text, result_text
from console.spectra_view import decade_ticks
from console.spinup import AT_SPEED, SpinUpEstimate
from daq.reader import RunFile
from procedures.procedure import Measurement, Verdict
from procedures.runner import RunSummary

from .conftest import COLD, WARM, outcome, rig_ready, run_async, start_procedure, wait_for


def text_of(app, selector: str) -> str:
    return str(app.query_one(selector, Static).render())


def reachable(box: VerticalScroll, content: Static) -> bool:
    """Every line of ``content`` can be scrolled into ``box``: nothing is cut off for good."""
    return box.max_scroll_y + box.scrollable_content_region.height >= content.outer_size.height > 0


# ---------------------------------------------------------------------------- no rig needed
def test_spin_up_estimate_follows_a_first_order_run_up_read_in_whole_percent():
    tau = 120.0 / math.log(100.0)  # 99 % in 120 s
    est = SpinUpEstimate()
    seen: list[tuple[float, float | None]] = []
    for i in range(0, 1200):
        t = i * 0.1
        f = math.floor(100 * (1 - math.exp(-t / tau))) / 100  # the relay node's whole percent
        seen.append((t, est.observe(t, f, spinning_up=True)))
    assert seen[0][1] is None  # not measurable at once
    for t, left in seen:
        if 10 <= t <= 115:  # from a third of the speed on: within 5 % (or a second)
            assert left == pytest.approx(120.0 - t, rel=0.05, abs=1.0), t
    assert est.observe(200.0, AT_SPEED, spinning_up=True) is None  # at speed: nothing left to say
    assert est.observe(201.0, 0.5, spinning_up=False) is None  # mode 1: the wheels run down


def test_parameters_box_takes_a_resume_the_way_fbs_run_does():
    from procedures.calibrations import catalogue

    cls = catalogue()["stopwatch"]
    proc, resume = parse_run_text(cls, 'channels=["X"] repetitions=1')
    assert resume is None and proc.params.channels == ["X"] and proc.params.repetitions == 1
    proc, resume = parse_run_text(cls, "--resume out/stopwatch.h5")
    assert resume == Path("out/stopwatch.h5")
    with pytest.raises(ValueError, match="with its own parameters"):
        parse_run_text(cls, "--resume out/stopwatch.h5 repetitions=2")


def test_result_text_names_every_measurement_file_and_the_resume(tmp_path):
    run = tmp_path / "stopwatch.h5"
    run.touch()
    ms = [Measurement(f"m{i}", 1.0 + i, "V") for i in range(5)]
    ms.append(Measurement("residual null rate X", 0.7, "urad/s", lo=-0.5, hi=0.5))
    summary = RunSummary(
        "stopwatch",
        run,
        "aborted: ProcedureAborted: aborted by the operator",
        Verdict.ABORTED,
        measurements=ms,
        steps_done=["mode 3", "channel X"],
        steps_planned=["a", "b", "c"],
        report=tmp_path / "stopwatch.md",
    )
    text = str(result_text(summary, (tmp_path / "stopwatch-X.png",)))
    for m in ms:
        assert f"{m.name}: " in text
    assert "residual null rate X: 0.7 urad/s  limits -0.5 .. 0.5  FAIL" in text
    assert (
        f"report {tmp_path / 'stopwatch.md'}" in text
        and f"plot   {tmp_path / 'stopwatch-X.png'}" in text
    )
    assert f"fbs run stopwatch --resume {run}" in text and "2 of 3 steps done" in text
    complete = dataclasses.replace(summary, status="complete", verdict=Verdict.FAIL)
    assert "resume" not in str(result_text(complete))


def test_channel_names_and_log_ticks():
    assert (
        meant("pickoff X") == "gyro_x"
        and meant("autocoll Y") == "ac_y_ctl"
        and meant("nothing") is None
    )
    why = unknown_channels(["pickoff X", "gyro_y"], ["gyro_x", "gyro_y"], "f.h5")
    assert (
        why
        == "f.h5 has no channel 'pickoff X' ('pickoff X' is gyro_x); its channels: gyro_x, gyro_y"
    )
    assert decade_ticks(0.0977, 100.0, "Hz") == (
        [0.1, 1.0, 10.0, 100.0],
        ["0.1", "1", "10", "100 Hz"],
    )
    assert decade_ticks(3e-7, 2e-5)[1] == ["1e-06", "1e-05"]
    assert decade_ticks(2.0, 8.0)[0] == [2.0, 5.0]  # less than a decade: 1-2-5 steps


# ---------------------------------------------------------------------------- against the rig
@pytest.mark.slow
@run_async
async def test_results_parameters_and_paths_are_shown_whole(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        cls = app.catalogue["stopwatch"]
        await start_procedure(pilot, "stopwatch", 'channels=["X"] repetitions=1')
        # every parameter with its default (stopwatch has 15), in a box that scrolls
        defaults = text_of(app, "#proc-defaults")
        params = dataclasses.asdict(cls.Params())
        assert len(params) >= 14 and f"{len(params)} parameters" in defaults
        for name in params:
            assert f"{name}=" in defaults, name
        assert reachable(
            app.query_one("#proc-about", VerticalScroll), app.query_one("#proc-defaults", Static)
        )
        await wait_for(pilot, lambda: app.last_summary is not None, what="the procedure to end")
        s = app.last_summary
        assert s.status == "complete" and len(s.measurements) >= 6
        await pilot.pause(0.2)
        result = " ".join(text_of(app, "#proc-result").split())
        for m in s.measurements:  # every one, the PASS/FAIL residual among them
            assert f"{m.name}: " in result, m.name
        assert any(
            m.name.startswith("residual null rate") and m.passed is not None for m in s.measurements
        )
        plots = sorted(out_dir.glob("stopwatch-*.png"))
        assert plots and s.report == out_dir / "stopwatch.md"
        for path in (s.file, s.report, *plots):  # each file by its whole path
            assert str(path) in result, path
        assert "resume" not in result  # a complete run has nothing to resume
        box = app.query_one("#proc-result-box", VerticalScroll)
        assert reachable(box, app.query_one("#proc-result", Static))
        box.scroll_end(animate=False)
        await pilot.pause(0.1)
        assert box.scroll_y == box.max_scroll_y


@pytest.mark.slow
@run_async
async def test_an_aborted_run_says_how_to_resume_and_f9_resumes_it(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        state, rig = app.worker_.state, app.worker_.rig
        # The rig thread waits at channel Y's start until F8 is in: the rig runs in virtual
        # time, and on a loaded box channel Y could otherwise end before the key lands.
        pressed, held = threading.Event(), threading.Event()
        poll = rig.adc.after_block

        def after_block() -> None:
            poll()
            p = state.get().procedure
            if p is not None and p.index >= 2 and not pressed.is_set():
                held.set()
                if not pressed.wait(60.0):  # a hang guard only
                    raise AssertionError("F8 never pressed")

        rig.adc.after_block = after_block
        await start_procedure(pilot, "stopwatch", 'channels=["X","Y"] repetitions=1')
        await wait_for(
            pilot,
            lambda: (p := state.get().procedure) is not None and p.index >= 2,
            what="channel X done",
        )
        await wait_for(pilot, held.is_set, what="the rig held at channel Y's start")
        await pilot.press("f8")
        pressed.set()
        rig.adc.after_block = poll
        await wait_for(pilot, lambda: app.last_summary is not None, what="the abort")
        first = app.last_summary
        assert first.verdict == "aborted" and "channel X" in first.steps_done
        await pilot.pause(0.2)
        result = " ".join(text_of(app, "#proc-result").split())
        assert f"resume f9 here, or: fbs run stopwatch --resume {first.file}" in result
        await pilot.press("f9")  # resume it here, as fbs run --resume does
        await wait_for(pilot, lambda: app.last_summary is not first, what="the resumed run")
        second = app.last_summary
        assert second.status == "complete" and second.steps_resumed == ["channel X"]
        assert second.file == out_dir / "stopwatch-2.h5"
        with RunFile(second.file) as rf:
            assert rf.meta["procedure"]["resumed_from"] == str(first.file)
            assert rf.meta["procedure"]["params"]["channels"] == ["X", "Y"]
        # a resume of a finished run is refused (as fbs run refuses it), and the panel is idle again
        app.query_one("#proc-params", Input).value = f"--resume {second.file}"
        await pilot.press("f7")
        await wait_for(
            pilot,
            lambda: (o := outcome(app, "procedure stopwatch")) is not None and not o.ok,
            what="the refusal",
        )
        assert "complete; nothing to resume" in outcome(app, "procedure stopwatch").text
        await pilot.pause(0.2)
        assert not app.w_procedures.running and "not started" in text_of(app, "#proc-step")


@pytest.mark.slow
@run_async
async def test_file_and_channel_names_are_the_ones_written_and_read(out_dir):
    out_dir.mkdir(parents=True)
    (out_dir / "recording.h5").touch()  # an earlier session's recording
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        # the meters name their channels as the recording, the spectra and the files do
        table = str(app.query_one("#meter-table").render()).splitlines()[1:]
        names = [row.split()[0] for row in table]
        assert names == [s.channel for s in app.specs] and set(names) <= set(app.adc_channels)
        assert names[:2] == ["gyro_x", "gyro_y"] and "pickoff" in table[0]
        await pilot.press("f4")
        box = app.query_one("#rec-path", Input)
        assert box.placeholder == f"blank: {out_dir / 'recording-2.h5'} (the next free name)"
        app.query_one("#rec-channels", Input).value = "pickoff X"  # the old meters' words
        await pilot.press("f7")
        await wait_for(
            pilot,
            lambda: (
                "refused recording: the ADC has no channel 'pickoff X' ('pickoff X' is gyro_x); "
                "its channels: " in log_text(app)
            ),
            what="the refusal",
        )
        assert state_phase(app) == "ready"
        app.query_one("#rec-channels", Input).value = "gyro_x,gyro_y"
        app.query_one("#rec-rate", Input).value = "200"
        await pilot.press("f7")
        await wait_for(
            pilot,
            lambda: (r := app.worker_.state.get().recording) is not None and r.samples >= 2000,
            what="10 s of samples",
        )
        assert (
            app.worker_.state.get().recording.path == out_dir / "recording-2.h5"
        )  # the name shown
        await wait_for(
            pilot,
            lambda: "recording-3.h5" in box.placeholder,
            what="the name taken, the next shown",
        )
        await pilot.press("f8")
        await wait_for(pilot, lambda: state_phase(app) == "ready", what="the recording closed")
        assert box.placeholder == f"blank: {out_dir / 'recording-3.h5'} (the next free name)"
        with RunFile(out_dir / "recording-2.h5") as rf:
            assert rf.status == "complete"
        # the spectra offer that recording, saying it is the last recording; a wrong name lists the right ones
        await pilot.press("f6")
        assert (
            app.query_one("#spec-path", Input).placeholder
            == f"blank: {out_dir / 'recording-2.h5'} (the last recording)"
        )
        app.query_one("#spec-channels", Input).value = "pickoff X,gyro_y"
        await pilot.press("f7")
        await wait_for(
            pilot, lambda: "has no channel" in text_of(app, "#spec-info"), what="the error"
        )
        info = " ".join(text_of(app, "#spec-info").split())
        assert "'pickoff X' is gyro_x" in info and info.endswith("its channels: gyro_x, gyro_y")
        # the spectra drawn on log axes: decade ticks on both axes of the PSD, a log frequency axis
        app.query_one("#spec-channels", Input).value = "gyro_x,gyro_y"
        await pilot.press("f7")
        await wait_for(pilot, lambda: app.w_spectra.view is not None, what="the spectra")
        await pilot.pause(0.3)
        psd, coh = (str(app.query_one(w).render()) for w in ("#spec-psd", "#spec-coh"))
        x_axis = psd.splitlines()[-1].split()
        assert x_axis[-2:] == ["100", "Hz"] and is_log_axis(x_axis[:-1]), (
            x_axis
        )  # .. Nyquist, in decades
        y_axis = [line.split("┤")[0].strip() for line in psd.splitlines() if "┤" in line]
        assert len(y_axis) >= 2 and is_log_axis(y_axis), y_axis
        assert coh.splitlines()[-1].split() == x_axis and "0.5┤" in coh
        assert str(app.query_one("#spec-psd").render()) == psd  # a repaint draws the same plot
        assert "the last recording" in text_of(app, "#spec-info")


def state_phase(app) -> str:
    return app.worker_.state.get().phase


def log_text(app) -> str:
    return " ".join(" ".join(str(line.text) for line in app.query_one("#event-log").lines).split())


def is_log_axis(labels: list[str]) -> bool:
    """Tick labels of a log axis: 1, 2 or 5 times a power of ten, each step at least x2."""
    values = sorted(float(v) for v in labels)
    mantissas = {round(v / 10 ** math.floor(math.log10(v)), 6) for v in values}
    return mantissas <= {1.0, 2.0, 5.0} and all(
        b >= 2 * a for a, b in zip(values, values[1:], strict=False)
    )


@pytest.mark.slow
@run_async
async def test_a_terminal_too_small_says_so(out_dir):
    app = ConsoleApp(WARM, out_dir=out_dir)
    async with app.run_test(size=(60, 18)) as pilot:
        await rig_ready(pilot)
        notice = app.query_one("#too-small", Static)
        assert notice.display and notice.region.height >= 1
        assert (
            f"terminal 60x18 is too small: the console needs {MIN_SIZE[0]}x{MIN_SIZE[1]}"
            in text_of(app, "#too-small")
        )
        await pilot.resize_terminal(*MIN_SIZE)
        await wait_for(pilot, lambda: not notice.display, what="the notice to go")
        await pilot.resize_terminal(79, 30)
        await wait_for(
            pilot, lambda: notice.display and "79x30" in text_of(app, "#too-small"), what="it again"
        )


@pytest.mark.slow
@run_async
async def test_spin_up_shows_its_time_and_an_interlock_reason_is_said_once(out_dir):
    from simhw.config import load_config

    app = ConsoleApp(COLD, out_dir=out_dir)
    async with app.run_test(size=(80, 24)) as pilot:
        await rig_ready(pilot)
        await pilot.press("f2", "h", "4", "r")  # refused: the wheels are stopped
        await wait_for(pilot, lambda: outcome(app, "release") is not None, what="the refusal")
        await wait_for(pilot, lambda: "ALARM" in text_of(app, "#mode-alarm"), what="the alarm")
        panel = " ".join(str(w.render()) for w in app.w_modes.query(Static))
        assert (
            panel.count("not at speed") == 1 and panel.count("not caged") == 1
        )  # said by the alarm only
        assert "mode 4 needs X Y Z XRD at speed and caged: refused (the alarm says why)" in panel
        assert "wheels 0 % (mode 2 spins them up)" in panel
        await pilot.press("h", "2", "r")
        await wait_for(pilot, lambda: app.worker_.state.get().relay.mode == 2, what="mode 2")
        state = app.worker_.state
        seen = []  # the snapshot as the predicate saw it: the wheels go on spinning up

        def a_third() -> bool:
            snap = state.get()
            if snap.relay.spin_fraction >= 0.3 and snap.spin_left_s is not None:
                seen.append(snap)
            return bool(seen)

        await wait_for(pilot, a_third, what="a third of the speed")
        snap = seen[0]
        tau = load_config(None).gyros.spin_up_time_s / math.log(100.0)
        truth = tau * math.log((1 - snap.relay.spin_fraction) / (1 - AT_SPEED))
        assert snap.spin_left_s == pytest.approx(truth, rel=0.1, abs=5.0)
        await wait_for(
            pilot,
            lambda: (
                ", at speed in about " in text_of(app, "#mode-gyros")
                and ", ~" in text_of(app, "#status")
            ),
            what="the estimate shown",
        )
        assert "ALARM" not in text_of(app, "#mode-alarm")
