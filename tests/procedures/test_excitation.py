"""The ``excitation`` procedure (thesis Ch. V C-D) end to end on the simulated rig, through
the drivers, against sim configs whose inertia, compensation corners and bearing stiffness
are drawn here and published nowhere the procedure looks (issue 22, acceptance A):

* the identified network within 1 dB and 5 deg of the simulated one over 0.3-50 Hz;
* the inertia within 5 %, the bearing stiffness within 10 %, each interval covering the truth.

The analysis alone is tested on independently generated data in
``tests/procedures/analysis/test_transfer.py``.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from drivers.rig import open_rig
from procedures.analysis.transfer import network_response
from procedures.calibrations import catalogue
from procedures.calibrations.excitation import Excitation, Params, excitation_signal
from procedures.runner import run_procedure
from simhw.config import load_config
from simhw.plant import linearized_poles
from tests.procedures.excitation_rigs import FAST, assert_roots_near_the_linearized, drawn_config
from tests.result_schema import assert_valid_result


def _truth_network(corners):
    p = {
        "gain": 1.0,
        "w1_rad_per_s": 0.15,
        "w2_rad_per_s": 10.0,
        "w3_rad_per_s": 30.0,
        "w4_rad_per_s": 200.0,
        "w5_rad_per_s": 1200.0,
        "w6_rad_per_s": 5000.0,
    }
    return p | corners


def test_excitation_is_in_the_catalogue_and_checks_its_parameters():
    assert catalogue()["excitation"] is Excitation
    with pytest.raises(ValueError, match="update"):
        Params(update_hz=300.0)
    with pytest.raises(ValueError, match="periods"):
        Params(excite_s=100.0)
    with pytest.raises(ValueError, match="axis"):
        Params(axis="Z")
    with pytest.raises(ValueError, match="mode"):
        Params(mode=6)


def test_excitation_signal_is_unit_rms_and_flat_in_its_band_only():
    x = excitation_signal(4000, 250.0, 0.5, 30.0, seed=3)
    assert np.sqrt(np.mean(x * x)) == pytest.approx(1.0)
    spec = np.abs(np.fft.rfft(x))
    f = np.fft.rfftfreq(4000, 1 / 250.0)
    inside = spec[(f >= 0.5) & (f <= 30.0)]
    assert np.allclose(inside, inside[0])
    assert np.max(spec[(f > 30.5) | (f < 0.45)]) < 1e-9 * inside[0]


@pytest.mark.slow
@pytest.mark.parametrize("k, axis", [(0, "X"), (1, "X"), (2, "Y")])
def test_excitation_identifies_drawn_network_inertia_and_stiffness(tmp_path, k, axis):
    rng = np.random.default_rng(220 + k)
    nominal_inertia = {"X": 0.70, "Y": 0.25}[axis]
    while (
        True
    ):  # a rig whose Mode-3 loop is stable with margin (a lab's is); the draw is the test's
        inertia = round(float(nominal_inertia * rng.uniform(0.7, 1.4)), 4)
        stiffness = round(float(rng.uniform(250, 700)), 1)
        corners = {
            "w2_rad_per_s": round(float(rng.uniform(7, 14)), 3),
            "w3_rad_per_s": round(float(rng.uniform(22, 40)), 3),
            "w4_rad_per_s": round(float(rng.uniform(150, 260)), 2),
        }
        cfg = drawn_config(tmp_path, axis, inertia, stiffness, corners)
        if np.max(linearized_poles(load_config(cfg), 3, axis).real) < -0.5:
            break
    with open_rig(f"sim?warm=1&seed={30 + k}&config={cfg}") as rig:
        s = run_procedure(Excitation(Params(axis=axis, **FAST)), rig, tmp_path / "out")
    assert s.exit_code == 0, s.error
    printed = s.json_result(Excitation(Params(axis=axis, **FAST)))  # `fbs run --json` (issue 37)
    assert_valid_result(printed)
    assert printed["simulated"] is True and printed["sim_config"]["path"] == str(cfg.resolve())
    v = s.values
    # the network: its tabulated response against the simulated one, 0.3-50 Hz
    table = v["network"]["response"]
    f = np.array(table["f_hz"])
    sel = f <= 50
    truth = network_response(f, _truth_network(corners))
    d_db = np.array(table["gain_db"]) - 20 * np.log10(np.abs(truth))
    d_deg = (np.array(table["phase_deg"]) - np.degrees(np.angle(truth)) + 180) % 360 - 180
    assert np.max(np.abs(d_db[sel])) < 1.0, (d_db, corners)
    assert np.max(np.abs(d_deg[sel])) < 5.0, (d_deg, corners)
    # the platform
    J, J_ci = v["inertia_kg_m2"][axis], v["inertia_kg_m2_ci95"][axis]
    K, K_ci = v["stiffness_Nm_per_rad"][axis], v["stiffness_Nm_per_rad_ci95"][axis]
    assert abs(J / inertia - 1) < 0.05 and J_ci[0] <= inertia <= J_ci[1], (J, J_ci, inertia)
    assert abs(K / stiffness - 1) < 0.10 and K_ci[0] <= stiffness <= K_ci[1], (K, K_ci, stiffness)
    # the damping: the gyro gimbals' (the spring bearing adds none)
    damping = load_config(cfg).platform[axis].gyro_damping_Nms
    D, D_ci = v["damping_Nms"][axis], v["damping_Nms_ci95"][axis]
    print(f"{axis}: J {J} {J_ci} / {inertia}; k {K} {K_ci} / {stiffness}; D {D} {D_ci} / {damping}")
    assert abs(D / damping - 1) < 0.10 and D_ci[0] <= damping <= D_ci[1], (D, D_ci, damping)
    # the data sheet's inertia (the sim publishes the drawn one) is only set beside it
    assert v["datasheet_inertia_kg_m2"] == pytest.approx(inertia)
    # the Mode-3 closed-loop roots (Table 5) against the linearized model of the drawn rig
    assert_roots_near_the_linearized(v["closed_loop"], load_config(cfg), 3, axis)
    saved = json.loads((tmp_path / "out" / "excitation.json").read_text())
    assert saved["verdict"] == "pass"
    md = (tmp_path / "out" / "excitation.md").read_text()
    assert "Compensation network" in md and "inertia_kg_m2" in md


@pytest.mark.slow
def test_excitation_on_dahl_bearings_says_k_and_d_are_describing_functions_at_its_amplitude(
    tmp_path,
):
    """The thesis rig's Dahl bearings (issue 38 items 2 and 3). k and D are the bearing's
    describing function at the excited motion: the JSON carries that motion's rms and says
    which figures depend on it, the summary and the report say "describing function at X urad
    rms". The damping of a hysteresis depends on frequency (it was printed resolved, 2.41 [2.20,
    2.62] against a viscous 1.17): unresolved, its interval holding the describing function's
    (eq. 5.12) and the offline equivalent-linear value. The stiffness's interval covers what
    the bearing is under this very excitation (``fbs.demo_truth.dahl_equivalent_linear``: its
    torque along the true angle of an offline run, 392.4 for 392.3 measured; the sinusoidal
    describing function at the same rms, 406.6, is 3.7 % above: the loop's noise dithers the
    friction). The network's corners come from inside the excited loop: w1 read +46 % with an
    interval wholly above the truth from the quiet record's H1; each corner's interval now covers
    the design value, or the corner is unresolved."""
    from fbs.demo_truth import dahl_at_amplitude, dahl_equivalent_linear
    from simhw.config import SimConfig

    with open_rig("sim?warm=1&seed=41") as rig:
        s = run_procedure(Excitation(Params(**FAST)), rig, tmp_path)
    assert s.exit_code == 0, s.error
    printed = s.json_result(Excitation(Params(**FAST)))
    assert_valid_result(printed)
    amp = printed["excitation_amplitude_urad"]["X"]
    assert 1.0 < amp < 4.0, amp
    dep = printed["amplitude_dependent"]
    assert (
        dep["stiffness_Nm_per_rad"]["X"]
        and dep["damping_Nms"]["X"]
        and not dep["inertia_kg_m2"]["X"]
    )
    cfg = SimConfig()
    eq = dahl_equivalent_linear(cfg, "X", float(s.values["level_V_rms"]))
    k_df, d_df, _ = dahl_at_amplitude(cfg, "X", amp, (eq.stiffness_Nm_per_rad / 0.70) ** 0.5)
    d_df += cfg.platform["X"].gyro_damping_Nms
    k, k_ci = printed["stiffness_Nm_per_rad"]["X"], printed["stiffness_Nm_per_rad_ci95"]["X"]
    d_ci = printed["damping_Nms_ci95"]["X"]
    print(
        f"amplitude {amp} urad rms; k {k} {k_ci}, equivalent linear {eq.stiffness_Nm_per_rad:.1f}, describing "
        f"function {k_df:.1f}; D {d_ci}, equivalent linear {eq.damping_Nms:.3f}, describing function {d_df:.3f}"
    )
    assert (
        printed["resolved"]["stiffness_Nm_per_rad"]["X"]
        and k_ci[0] <= eq.stiffness_Nm_per_rad <= k_ci[1]
    )
    assert printed["damping_Nms"]["X"] is None and not printed["resolved"]["damping_Nms"]["X"]
    assert d_ci[0] <= d_df <= d_ci[1] and d_ci[0] <= eq.damping_Nms <= d_ci[1], (d_ci, d_df, eq)
    assert "depends on frequency" in s.values["platform_why_unresolved"]["damping_Nms"]
    J_ci = printed["inertia_kg_m2_ci95"]["X"]
    assert printed["resolved"]["inertia_kg_m2"]["X"] and J_ci[0] <= 0.70 <= J_ci[1]
    label = f"describing function at {amp:.3g} urad rms"
    assert any(label in m.name for m in s.measurements if m.name.startswith("stiffness_Nm_per_rad"))
    assert label in (tmp_path / "excitation.md").read_text()
    net = printed["network"]
    for corner, truth in (
        ("w1_rad_per_s", 0.15),
        ("w2_rad_per_s", 10.0),
        ("w3_rad_per_s", 30.0),
        ("w4_rad_per_s", 200.0),
    ):
        lo, hi = net[f"{corner}_ci95"]
        print(corner, net[corner], [lo, hi], net["resolved"][corner])
        assert not net["resolved"][corner] or lo <= truth <= hi, (corner, net[corner], lo, hi)
    assert net["resolved"]["w1_rad_per_s"]


@pytest.mark.slow
def test_excitation_pickoff_noise_is_the_simulated_within_20_percent(tmp_path):
    """Issue 22 B: the gyro's part incoherent with V_Td, in 1-50 Hz, against the simulated
    pickoff noise there (its white level and the lines in the band), on a rig with another
    pickoff noise level than the thesis's."""
    from simhw.config import SimConfig
    from simhw.simulator import pickoff_white_psd

    cfg_path = tmp_path / "noisy.toml"
    cfg_path.write_text("[gyro.X]\npickoff_noise_rms_urad = 9.5\n")
    with open_rig(f"sim?warm=1&seed=43&config={cfg_path}") as rig:
        s = run_procedure(Excitation(Params(**FAST)), rig, tmp_path / "out")
    assert s.exit_code == 0, s.error
    g = load_config(cfg_path).gyro["X"]
    assert g.pickoff_noise_rms_urad != SimConfig().gyro["X"].pickoff_noise_rms_urad
    white = pickoff_white_psd(g.pickoff_noise_rms_urad, g.pickoff_lines) * 1e12
    lines = sum(a**2 / 2 for fl, a in g.pickoff_lines if 1.0 <= fl <= 50.0)
    expected = (white * 49.0 + lines) ** 0.5
    got = s.values["pickoff_noise_urad_rms"]["X"]
    print(f"pickoff noise 1-50 Hz: measured {got:.4g} urad rms, simulated {expected:.4g}")
    assert abs(got / expected - 1) < 0.20, (got, expected)


@pytest.mark.slow
def test_an_aborted_excitation_leaves_the_rig_safe_and_resumes(tmp_path):
    """Abort while V_Td is being driven: the rig is left in the safe state (mode 1, V_Td read
    back 0), the file closed "aborted"; the resumed run takes the quiet record over, probes and
    excites again, and identifies the rig."""
    import threading

    from daq.reader import RunFile
    from procedures.resume import load_resume

    stop = threading.Event()

    def listener(progress):
        if progress.step == "excite" and progress.fraction > 0:
            stop.set()

    with open_rig("sim?warm=1&seed=44") as rig:
        first = run_procedure(
            Excitation(Params(**FAST)), rig, tmp_path, progress=listener, abort=stop
        )
        assert first.verdict == "aborted"
        assert rig.is_safe()
        assert rig.commands.command_torque_V("X") == 0.0
        assert "quiet" in first.steps_done and "excite" not in first.steps_done
        with RunFile(first.file) as rf:
            assert rf.status.startswith("aborted")
        second = run_procedure(
            Excitation(Params(**FAST)), rig, tmp_path, resume=load_resume(first.file, Excitation)
        )
    assert second.exit_code == 0, second.error
    assert second.steps_resumed == ["quiet"]
    assert abs(second.values["inertia_kg_m2"]["X"] / 0.70 - 1) < 0.05
