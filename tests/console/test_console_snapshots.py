"""Issue 7, acceptance A: the main screens pinned at 80x24 (pytest-textual-snapshot).

Deterministic by construction: a warm seeded rig in virtual time (mode 3, caged, outputs
zero), the meter refresh off (``live_meters=False``) with a fixed meter frame drawn instead,
and no rig time on the pinned screens. Regenerate with ``--snapshot-update`` after an
intended change, and look at the SVGs before committing them.
"""

from __future__ import annotations

import math

import pytest

from console.app import ConsoleApp
from console.meterdata import MeterSnapshot
from console.spectra import compute_view

from .conftest import WARM, rig_ready

pytestmark = pytest.mark.slow

SIZE = (80, 24)

#: a plausible frame of the warm rig, fixed: pickoffs near null, torquers holding earth rate
FRAME_V = {"gyro_x": 0.0021, "gyro_y": -0.0094, "gyro_z": 0.0152, "gyro_xrd": 0.3311, "torq_x": -1.8431,
           "torq_y": 0.0079, "torq_z": -1.3142, "torq_xrd": -1.7497, "ac_x_ctl": -0.0006, "ac_y_ctl": 0.0004}


def fixed_frame() -> MeterSnapshot:
    hist = {"gyro_x": tuple(0.004 * math.sin(i / 6) for i in range(150)),
            "torq_x": tuple(-1.843 + 0.002 * math.cos(i / 9) for i in range(150))}
    return MeterSnapshot(1, dict(FRAME_V), hist)


def console(out_dir) -> ConsoleApp:
    return ConsoleApp(WARM, out_dir=out_dir, live_meters=False)


async def settle(pilot) -> None:
    await rig_ready(pilot)
    pilot.app.show_meter_frame(fixed_frame())
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
    view = compute_view(__import__("pathlib").Path("spectra.h5"), ("gyro_x", "gyro_y"))

    async def spectra(pilot) -> None:
        await settle(pilot)
        await pilot.press("f6")
        pilot.app.w_spectra.draw(view)
        await pilot.pause(0.3)

    assert snap_compare(console(out_dir), terminal_size=SIZE, run_before=spectra)
