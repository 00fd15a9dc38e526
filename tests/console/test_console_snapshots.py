"""Issue 7, acceptance A, and issue 20, acceptance B: the main screens pinned at 80x24 and
120x40 (pytest-textual-snapshot).

Deterministic by construction: a warm seeded rig in virtual time (mode 3, caged, outputs
zero), the meter refresh off (``live_meters=False``) with a fixed meter frame drawn instead,
a fixed event log (its wall-clock stamps in UTC), and no other rig time on the pinned screens.
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
from console.spectra import compute_view
from console.state import Phase, RecordingInfo, RigEventItem

from .conftest import WARM, rig_ready

pytestmark = pytest.mark.slow

SIZE = (80, 24)
LARGE = (120, 40)

#: a plausible frame of the warm rig, fixed: pickoffs near null, torquers holding earth rate
FRAME_V = {"gyro_x": 0.0021, "gyro_y": -0.0094, "gyro_z": 0.0152, "gyro_xrd": 0.3311, "torq_x": -1.8431,
           "torq_y": 0.0079, "torq_z": -1.3142, "torq_xrd": -1.7497, "ac_x_ctl": -0.0006, "ac_y_ctl": 0.0004}


def fixed_frame() -> MeterSnapshot:
    hist = {"gyro_x": tuple(0.004 * math.sin(i / 6) for i in range(150)),
            "torq_x": tuple(-1.843 + 0.002 * math.cos(i / 9) for i in range(150))}
    return MeterSnapshot(1, dict(FRAME_V), hist)


def console(out_dir) -> ConsoleApp:
    return ConsoleApp(WARM, out_dir=out_dir, live_meters=False)


#: the event log pinned: the kinds of line an operator meets (2024-05-17 09:30 UTC on)
EVENTS = (RigEventItem(0.0, "console", "rig sim?warm=1&seed=3&watchdog=5 open (virtual time)", 1715938200.0),
          RigEventItem(12.5, "refused", "set-point: torquer bias (V) on gyro channel X 20.0 is outside +-8.07671 "
                       "(3.5 x earth rate at the nominal K_TO); nothing was sent", 1715938212.5),
          RigEventItem(20.25, "setpoint", "torquer bias X +0.0000 -> +0.2500 V at 1 V/s in 6 step(s), 0.25 s; "
                       "read back +0.2502 V", 1715938220.25),
          RigEventItem(31.0, "alarm", "mode 7 is not allowed (modes 1-6 only; 0 and 7 are disallowed and light "
                       "the alarm); the rig stays in its present mode", 1715938231.0))


@pytest.fixture(autouse=True)
def utc(monkeypatch):
    monkeypatch.setenv("TZ", "UTC")
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


def test_spectra_screen(snap_compare, out_dir, tmp_path, monkeypatch):
    from fbs.simulate import simulate_to_file
    from simhw.params import load_config

    monkeypatch.chdir(tmp_path)   # the view names its file: a relative name keeps the screen fixed
    simulate_to_file(load_config(None), "spectra.h5", mode=3, duration_s=60.0, rate_hz=200.0, seed=5)
    view = compute_view(Path("spectra.h5"), ("gyro_x", "gyro_y"))

    async def spectra(pilot) -> None:
        await settle(pilot)
        await pilot.press("f6")
        pilot.app.w_spectra.draw(view)
        await pilot.pause(0.3)

    assert snap_compare(console(out_dir), terminal_size=SIZE, run_before=spectra)


@pytest.mark.parametrize("key", ["f1", "f2", "f3", "f4", "f5"])
def test_main_screens_at_120x40(snap_compare, out_dir, key):
    assert snap_compare(console(out_dir), press=[key], terminal_size=LARGE, run_before=settle)


def test_help_screen(snap_compare, out_dir):
    assert snap_compare(console(out_dir), press=["f2", "question_mark"], terminal_size=SIZE, run_before=settle)


def test_quit_question_while_recording(snap_compare, out_dir):
    async def asked(pilot) -> None:
        await settle(pilot)
        app = pilot.app
        live = replace(app.worker_.state.get(), phase=Phase.RECORDING,       # a recording, pinned
                       recording=RecordingInfo(Path("out/recording.h5"), 1000.0, ("gyro_x",) * 16, 83.4, 83400))
        app.push_screen(QuitScreen(what_quit_closes(live)))
        await pilot.pause(0.3)

    assert snap_compare(console(out_dir), terminal_size=SIZE, run_before=asked)
