"""The ``excitation`` procedure in the gyro-stabilized modes (issue 22 C) end to end on the
simulated rig: the closed-loop roots of Table 6 against the linearized model of a drawn rig.
The Mode-3 runs are in ``test_excitation.py``."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.rig import open_rig
from procedures.calibrations.excitation import Excitation, Params
from procedures.runner import run_procedure
from simhw.config import load_config, nominal_pickoff_lines
from simhw.plant import linearized_poles
from tests.procedures.excitation_rigs import FAST, assert_roots_near_the_linearized, drawn_config


@pytest.mark.slow
@pytest.mark.parametrize("k, mode, axis, stopwatch", [(0, 4, "X", True), (1, 5, "Y", False)])
def test_gyro_mode_closed_loop_roots_are_the_linearized_models(tmp_path, k, mode, axis, stopwatch):
    """Issue 22 C: in the gyro-stabilized modes the closed-loop roots (Table 6: c1, the platform
    pair, c4), from the loop closed over the parts the run identifies, within 10 % of the
    linearized model of a drawn rig (spring bearings, drawn inertia, corners, pickoff scale and
    noise). The pickoff scale is never the data sheet's: the stopwatch's where the campaign
    has it (here a stand-in, the drawn K_g to +-0.3 %), else measured in the run, where the
    gyro's cross-axis coupling reaches it (issue 38: an allowance). Either way the platform
    pair's interval holds the loop alone's pair (before issue 38 the in-loop gain, 1.2-1.7 %
    off, put it outside on 4 of 12 drawn rigs)."""
    rng = np.random.default_rng(400 + k)
    nominal_inertia = {"X": 0.70, "Y": 0.25}[axis]
    while True:
        inertia = round(float(nominal_inertia * rng.uniform(0.8, 1.25)), 4)
        stiffness = round(float(rng.uniform(250, 600)), 1)
        corners = {
            "w2_rad_per_s": round(float(rng.uniform(8, 12)), 3),
            "w3_rad_per_s": round(float(rng.uniform(25, 36)), 3),
            "w4_rad_per_s": round(float(rng.uniform(170, 240)), 2),
        }
        cfg = drawn_config(tmp_path, axis, inertia, stiffness, corners)
        rms = round(float(rng.uniform(4.0, 12.0)), 2)
        cfg.write_text(
            cfg.read_text() + f"[gyro.{axis}]\npickoff_scale_mV_per_urad = "
            f"{round(float(rng.uniform(5.5, 7.5)), 3)}\npickoff_noise_rms_urad = {rms}\n"
            f"pickoff_lines = {nominal_pickoff_lines(rms)!r}\n"
        )
        if np.max(linearized_poles(load_config(cfg), mode, axis).real) < -0.05:
            break
    kg = load_config(cfg).gyro[axis].pickoff_scale_mV_per_urad
    prior = (
        {
            "stopwatch": {
                "K_g_mV_per_urad": {axis: kg},
                "K_g_mV_per_urad_ci95": {axis: [kg * 0.997, kg * 1.003]},
            }
        }
        if stopwatch
        else {}
    )
    with open_rig(f"sim?warm=1&seed={60 + k}&config={cfg}") as rig:
        s = run_procedure(
            Excitation(Params(axis=axis, mode=mode, mode_settle_s=40.0, **FAST), prior=prior),
            rig,
            tmp_path / "out",
        )
        assert rig.relays.status().mode == 3  # the procedure hands the rig back in Mode 3
    assert s.exit_code == 0, s.error
    cl = s.values["closed_loop"]
    assert_roots_near_the_linearized(cl, load_config(cfg), mode, axis)
    assert abs(cl["sensor_mV_per_urad"] / kg - 1) < 0.05, (cl["sensor_mV_per_urad"], kg)
    assert cl["sensor_from"] == ("stopwatch" if stopwatch else "measured in the loop")
    assert ("sensor_in_loop_mV_per_urad" in cl) == stopwatch
    lin = linearized_poles(load_config(cfg), mode, axis)
    pair = complex(*cl["roots"]["platform_pair"]["pole"])
    lo, hi = cl["roots"]["platform_pair"]["w_rad_per_s_ci95"]
    assert lo <= abs(lin[np.argmin(np.abs(lin - pair))]) <= hi, (lo, hi, lin)
    md = (tmp_path / "out" / "excitation.md").read_text()
    assert f"Closed-loop roots, Mode {mode}" in md and "Table 6" in md
