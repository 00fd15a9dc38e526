"""Issue 7, acceptance A, and issue 20, acceptance B: the main screens pinned at 80x24 and
120x40, and the notice of a terminal too small at 60x18 (pytest-textual-snapshot).

Deterministic by construction: a warm seeded rig in virtual time (mode 3, caged, outputs
zero), the meter refresh off (``live_meters=False``) with a fixed meter frame drawn instead,
a fixed event log (its wall-clock stamps in UTC), a fixed procedure summary, the files named
relative to the test's own directory (``out/``), and no other rig time on the pinned screens.
Regenerate with ``--snapshot-update`` after an intended change, and look at the SVGs before
committing them.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path

import pytest
from textual.widgets import RichLog

from console.app import ConsoleApp
from console.meterdata import MeterSnapshot
from console.quitscreen import QuitScreen, what_quit_closes
from console.spectra_view import compute_view
from console.state import Phase, RecordingInfo, RigEventItem
from procedures.procedure import Measurement, Verdict
from procedures.runner import RunSummary

from .conftest import WARM, rig_ready

pytestmark = pytest.mark.slow

SIZE = (80, 24)
LARGE = (120, 40)
SMALL = (60, 18)

#: a plausible frame of the warm rig, fixed: pickoffs near null, torquers holding earth rate
FRAME_V = {
    "gyro_x": 0.0021,
    "gyro_y": -0.0094,
    "gyro_z": 0.0152,
    "gyro_xrd": 0.3311,
    "torq_x": -1.8431,
    "torq_y": 0.0079,
    "torq_z": -1.3142,
    "torq_xrd": -1.7497,
    "ac_x_ctl": -0.0006,
    "ac_y_ctl": 0.0004,
}


def fixed_frame() -> MeterSnapshot:
    hist = {
        "gyro_x": tuple(0.004 * math.sin(i / 6) for i in range(150)),
        "torq_x": tuple(-1.843 + 0.002 * math.cos(i / 9) for i in range(150)),
    }
    return MeterSnapshot(1, dict(FRAME_V), hist)


def console(out_dir) -> ConsoleApp:
    # ``out_dir`` is the fixture's, but the screens name files relative to the test's directory
    return ConsoleApp(WARM, out_dir=Path("out"), live_meters=False)


#: the event log pinned: the kinds of line an operator meets (2024-05-17 09:30 UTC on)
EVENTS = (
    RigEventItem(
        0.0, "console", "rig sim?warm=1&seed=3&watchdog=5 open (virtual time)", 1715938200.0
    ),
    RigEventItem(
        12.5,
        "refused",
        "set-point: torquer bias (V) on gyro channel X 20.0 is outside +-8.07671 "
        "(3.5 x earth rate at the nominal K_TO); nothing was sent",
        1715938212.5,
    ),
    RigEventItem(
        20.25,
        "setpoint",
        "torquer bias X +0.0000 -> +0.2500 V at 1 V/s in 6 step(s), 0.25 s; read back +0.2502 V",
        1715938220.25,
    ),
    RigEventItem(
        31.0,
        "alarm",
        "mode 7 is not allowed (modes 1-6 only; 0 and 7 are disallowed and light "
        "the alarm); the rig stays in its present mode",
        1715938231.0,
    ),
)


#: a stopwatch run of one channel, as the console shows it at the end (a residual out of limits)
MEASUREMENTS = (
    Measurement(
        "K_g X (stopwatch, mean of 1 repetitions)", 6.02806, "mV/urad", lo=4.5225, hi=7.5375
    ),
    Measurement("K_g X repetition spread (std/mean)", 0.0, "", hi=0.02),
    Measurement("K_g X least-squares ramp slope", 6.01805, "mV/urad", stderr=0.014),
    Measurement("h/k X (fitted)", None, "s"),
    Measurement("restraint correction X", 0.0124492, "%"),
    Measurement("residual null rate X", 0.6208821, "urad/s", lo=-0.5, hi=0.5),
)


def summary(aborted: bool = False) -> tuple[RunSummary, tuple[Path, ...]]:
    run = Path("out/stopwatch.h5")
    run.parent.mkdir(exist_ok=True)
    run.touch()  # the file a resume continues is there
    if aborted:
        return RunSummary(
            "stopwatch",
            run,
            "aborted: ProcedureAborted: aborted by the operator",
            Verdict.ABORTED,
            steps_done=["mode 3", "channel X"],
            steps_planned=["mode 3", "channel X", "channel Y"],
            error="ProcedureAborted: aborted by the operator",
            report=Path("out/stopwatch.md"),
        ), ()
    return (
        RunSummary(
            "stopwatch",
            run,
            "complete",
            Verdict.FAIL,
            measurements=list(MEASUREMENTS),
            steps_done=["mode 3", "channel X"],
            steps_planned=["mode 3", "channel X"],
            report=Path("out/stopwatch.md"),
        ),
        (Path("out/stopwatch-X.png"), Path("out/stopwatch-ramps.png")),
    )


@pytest.fixture(autouse=True)
def utc(monkeypatch, tmp_path):
    monkeypatch.setenv("TZ", "UTC")
    monkeypatch.chdir(tmp_path)  # the screens name files under out/, whatever the test's directory
    time.tzset()
    yield
    monkeypatch.undo()
    time.tzset()


async def settle(pilot) -> None:
    await rig_ready(pilot)
    app = pilot.app
    app.show_meter_frame(fixed_frame())
    await pilot.pause(0.2)
    app.worker_.events.drain()
    app.query_one("#event-log", RichLog).clear()
    app.w_recording.log_events(list(EVENTS))
    await pilot.pause(0.3)


def test_meters_screen(snap_compare, out_dir):
    assert snap_compare(console(out_dir), terminal_size=SIZE, run_before=settle)


def test_modes_screen(snap_compare, out_dir):
    assert snap_compare(console(out_dir), press=["f2"], terminal_size=SIZE, run_before=settle)


def test_modes_screen_with_the_alarm_lit(snap_compare, out_dir):
    async def alarm(pilot) -> None:
        await settle(pilot)
        await pilot.press("f2", "h", "7")
        await pilot.pause(0.5)
        app = pilot.app
        while not any(o.what == "select mode 7" for o in app.outcomes):
            await pilot.pause(0.05)
        await pilot.press("escape")
        app.clear_notifications()
        await pilot.pause(0.6)

    assert snap_compare(console(out_dir), terminal_size=SIZE, run_before=alarm)


def test_setpoints_screen(snap_compare, out_dir):
    assert snap_compare(console(out_dir), press=["f3"], terminal_size=SIZE, run_before=settle)


def test_recording_screen(snap_compare, out_dir):
    assert snap_compare(console(out_dir), press=["f4"], terminal_size=SIZE, run_before=settle)


def test_procedures_screen(snap_compare, out_dir):
    assert snap_compare(console(out_dir), press=["f5"], terminal_size=SIZE, run_before=settle)


def procedure_result(aborted: bool = False):
    async def ended(pilot) -> None:
        await settle(pilot)
        await pilot.press("f5")
        while not pilot.app.catalogue:
            await pilot.pause(0.05)
        pilot.app.w_procedures.query_one("#proc-name").value = "stopwatch"
        pilot.app.w_procedures.finished(*summary(aborted))
        await pilot.pause(0.3)

    return ended


def test_procedure_result_screen(snap_compare, out_dir):
    assert snap_compare(console(out_dir), terminal_size=SIZE, run_before=procedure_result())


def test_procedure_aborted_screen(snap_compare, out_dir):
    assert snap_compare(
        console(out_dir), terminal_size=SIZE, run_before=procedure_result(aborted=True)
    )


@pytest.fixture
def spectra_view():
    from fbs.simulate import simulate_to_file
    from simhw.config import load_config

    # the view names its file: a relative name keeps the screen fixed
    simulate_to_file(
        load_config(None), "spectra.h5", mode=3, duration_s=60.0, rate_hz=200.0, seed=5
    )
    view = compute_view(Path("spectra.h5"), ("gyro_x", "gyro_y"))

    async def spectra(pilot) -> None:
        await settle(pilot)
        await pilot.press("f6")
        pilot.app.w_spectra.offer(view.path, "the last recording")
        pilot.app.w_spectra.draw(view, "the last recording")
        await pilot.pause(0.3)

    return spectra


def test_spectra_screen(snap_compare, out_dir, spectra_view):
    assert snap_compare(console(out_dir), terminal_size=SIZE, run_before=spectra_view)


@pytest.mark.parametrize("key", ["f1", "f2", "f3", "f4", "f5"])
def test_main_screens_at_120x40(snap_compare, out_dir, key):
    assert snap_compare(console(out_dir), press=[key], terminal_size=LARGE, run_before=settle)


def test_spectra_at_120x40(snap_compare, out_dir, spectra_view):
    assert snap_compare(console(out_dir), terminal_size=LARGE, run_before=spectra_view)


def test_procedure_result_at_120x40(snap_compare, out_dir):
    assert snap_compare(console(out_dir), terminal_size=LARGE, run_before=procedure_result())


def test_terminal_too_small_at_60x18(snap_compare, out_dir):
    assert snap_compare(console(out_dir), press=["f2"], terminal_size=SMALL, run_before=settle)


def test_help_screen(snap_compare, out_dir):
    assert snap_compare(
        console(out_dir), press=["f2", "question_mark"], terminal_size=SIZE, run_before=settle
    )


def test_quit_question_while_recording(snap_compare, out_dir):
    async def asked(pilot) -> None:
        await settle(pilot)
        app = pilot.app
        live = replace(
            app.worker_.state.get(),
            phase=Phase.RECORDING,  # a recording, pinned
            recording=RecordingInfo(
                Path("out/recording.h5"), 1000.0, ("gyro_x",) * 16, 83.4, 83400
            ),
        )
        app.push_screen(QuitScreen(what_quit_closes(live)))
        await pilot.pause(0.3)

    assert snap_compare(console(out_dir), terminal_size=SIZE, run_before=asked)
