"""earth-rate and stopwatch: their numerics on synthetic data, and the procedures against sim
rigs whose values they must find by measurement (acceptance A, B)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.rig import open_rig
from procedures.analysis.earth_rate import fit_horizontal, fit_vertical, omega_z
from procedures.analysis.stopwatch import channel_result
from procedures.analysis.stopwatch import crossing_interval as _crossing_interval
from procedures.analysis.stopwatch import restraint_fit as _restraint_fit
from procedures.analysis.stopwatch import smooth as _smooth
from procedures.calibrations.earth_rate import EarthRate
from procedures.calibrations.stopwatch import Stopwatch
from procedures.runner import run_procedure
from simhw.geometry import earth_rate_platform, platform_axes_enu

OMEGA = 7.292115e-5
LAT = 37.43


# ---------------------------------------------------------------------------- earth-rate numerics
def _torquer(ch: str, tilt: float, spindle: float, kto: float, drift: float, psi0: float) -> float:
    """V_T = -(Omega_i + d)/K_TO with Omega_i from simhw's own table geometry (independent of the fit)."""
    axes = platform_axes_enu(math.radians(tilt), math.radians(spindle), math.radians(psi0))
    w = earth_rate_platform(math.radians(LAT), OMEGA, axes)
    w_i = {"X": w[0], "XRD": w[0], "Y": w[1], "Z": w[2]}[ch]
    return -(w_i + drift * 1e-6) / (kto * 1e-6)


@settings(max_examples=40, deadline=None)
@given(kto=st.floats(20, 50), drift=st.floats(-2, 2), psi0=st.floats(-3, 3), ch=st.sampled_from(["X", "Y", "XRD"]))
def test_horizontal_fit_recovers_the_geometry(kto, drift, psi0, ch):
    psi = np.arange(12) * 30.0
    v = np.array([_torquer(ch, 0.0, p, kto, drift, psi0) for p in psi])
    f = fit_horizontal(ch, psi, v, OMEGA * math.cos(math.radians(LAT)), np.arange(12))
    assert f.kto_urad_per_s_per_V == pytest.approx(kto, rel=1e-9)
    assert f.drift_urad_per_s == pytest.approx(drift, abs=1e-7)
    assert f.psi0_deg == pytest.approx(psi0, abs=1e-7)


@settings(max_examples=40, deadline=None)
@given(kto=st.floats(20, 50), drift=st.floats(-2, 2), psi0=st.floats(-3, 3))
def test_vertical_fit_recovers_z(kto, drift, psi0):
    tilts = np.array([0, 22.5, 45, 67.5, 90, 67.5, 45, 22.5, 0.0])
    v = np.array([_torquer("Z", t, 90.0, kto, drift, psi0) for t in tilts])
    f = fit_vertical("Z", tilts, v, omega_z(tilts, LAT, OMEGA, psi0), np.arange(len(tilts)))
    assert f.kto_urad_per_s_per_V == pytest.approx(kto, rel=1e-9)
    assert f.drift_urad_per_s == pytest.approx(drift, abs=1e-7)


def test_fit_standard_errors_are_honest():
    """Noise of known size: the stated standard error covers the truth at about its rate."""
    rng = np.random.default_rng(4)
    psi = np.arange(12) * 30.0
    clean = np.array([_torquer("X", 0.0, p, 31.6, 0.35, 0.12) for p in psi])
    z = []
    for _ in range(400):
        f = fit_horizontal("X", psi, clean + rng.normal(0, 2e-3, 12), OMEGA * math.cos(math.radians(LAT)))
        z.append((f.kto_urad_per_s_per_V - 31.6) / f.kto_se)
    z = np.array(z)
    assert 0.8 < z.std() < 1.25 and abs(np.mean(np.abs(z) < 1.96) - 0.95) < 0.04


# ---------------------------------------------------------------------------- stopwatch numerics
def test_crossing_interval_of_an_exact_ramp():
    rate = 200.0
    t = np.arange(0, 30, 1 / rate)
    vg = -1.5 + 0.1 * t                       # crosses -1 at 5 s and +1 at 25 s
    assert _crossing_interval(t, vg, -1.0, 1.0, +1, 1.0, rate) == pytest.approx(20.0, abs=1e-6)
    assert _crossing_interval(t, -vg, -1.0, 1.0, -1, 1.0, rate) == pytest.approx(20.0, abs=1e-6)


def test_smooth_is_a_centred_average():
    y = np.arange(10.0)
    assert _smooth(y, 3)[1:-1] == pytest.approx(y[1:-1])


def test_restraint_fit_recovers_slope_and_h_over_k():
    """Exact solution of V_g' = a (V_T - V_T0) - k (V_g - V_g0) + c under bias steps and holds."""
    rate, a, k, c = 200.0, 0.19, 1 / 500.0, 2e-4
    t = np.arange(0, 400, 1 / rate)
    vt = np.where((t % 100) < 30, 0.3, np.where((t % 100) < 50, 0.0, np.where((t % 100) < 80, -0.3, 0.0)))
    vg = np.empty_like(t)
    vg[0] = 0.2
    for i in range(1, len(t)):  # exact per step for piecewise-constant input
        drive = (a * vt[i - 1] + c) / k + 0.2
        vg[i] = drive + (vg[i - 1] - drive) * math.exp(-k / rate)
    fit = _restraint_fit(t, vg, vt, vt_null=0.0, vg0=0.2, dt_s=0.5)
    assert fit["a"] == pytest.approx(a, rel=1e-3)
    assert fit["k"] == pytest.approx(k, rel=2e-2)
    assert fit["c"] == pytest.approx(c, rel=5e-2)  # 0.5 s means blur the bias steps a little


def test_restraint_correction_is_x_coth_x():
    tau = 400.0
    r = {"ch": "X", "kto": 31.6, "kto_from": "given", "dVg": 2.0, "null_slope": 0.0,
         "ramps": [[-1, 20.0, -0.3], [1, 20.0, 0.3]], "fit": {"a": 0.057, "a_se": 1e-4, "k": 1 / tau, "k_se": 1e-5}}
    res = channel_result(r)
    naive = 2.0 / (20.0 * 0.3 * 31.6) * 1e3
    x = 20.0 / (2 * tau)
    assert res.naive[0] == pytest.approx(naive)
    assert res.kg == pytest.approx(naive * x / math.tanh(x))
    assert res.correction == pytest.approx(x / math.tanh(x) - 1)
    assert res.tau_s == pytest.approx(tau)


# ---------------------------------------------------------------------------- on the simulated rig
def _toml(values: dict) -> str:
    lines = []
    for section, kv in values.items():
        lines.append(f"[{section}]")
        lines += [f"{k} = {v!r}" for k, v in kv.items()]
    return "\n".join(lines) + "\n"


def _draw(seed: int) -> dict:
    """A sim rig with other torquer and pickoff scale factors, drifts and table offset."""
    rng = np.random.default_rng(seed)
    cfg = {"table": {"base_azimuth_offset_deg": float(rng.uniform(-1.0, 1.0))}}
    for ch, kto, kg in (("X", 31.6, 6.03), ("Y", 33.4, 6.70), ("Z", 34.1, 7.51), ("XRD", 32.0, 5.74)):
        cfg[f"gyro.{ch}"] = {"torquer_scale_urad_per_s_per_V": float(kto * rng.uniform(0.88, 1.12)),
                             "pickoff_scale_mV_per_urad": float(kg * rng.uniform(0.85, 1.15)),
                             "fixed_drift_urad_per_s": float(rng.uniform(-0.8, 0.8))}
    return cfg


@pytest.mark.slow
@pytest.mark.parametrize("seed", [11, 23])
def test_earth_rate_and_stopwatch_find_a_random_rig(tmp_path, seed):
    """Acceptance B: K_TO within 0.5 %, K_g within 2 % of values the procedures were never told."""
    cfg = _draw(seed)
    path = tmp_path / "rig.toml"
    path.write_text(_toml(cfg))
    with open_rig(f"sim?warm=1&seed={seed}&watchdog=5&config={path}") as rig:
        er = run_procedure(EarthRate(), rig, tmp_path)
        assert er.verdict == "pass", er.error or [m for m in er.measurements if m.passed is False]
        sw = run_procedure(Stopwatch(prior={"earth-rate": er.values}), rig, tmp_path)
        assert sw.verdict == "pass", sw.error or [m for m in sw.measurements if m.passed is False]
    for ch in ("X", "Y", "Z", "XRD"):
        g = cfg[f"gyro.{ch}"]
        assert er.values["K_TO_urad_per_s_per_V"][ch] == pytest.approx(g["torquer_scale_urad_per_s_per_V"], rel=5e-3)
        assert sw.values["K_g_mV_per_urad"][ch] == pytest.approx(g["pickoff_scale_mV_per_urad"], rel=2e-2)
    # the table's azimuth offset is found too (X, Y, XRD each see it)
    psi0 = [m.value for m in er.measurements if m.name.startswith("table azimuth misalignment")]
    assert np.allclose(psi0, cfg["table"]["base_azimuth_offset_deg"], atol=0.15)
