"""An independent Mode-3 data generator for the model-gap workflow's tests.

The gap workflow uses ``simhw`` as its model. Tests that feed it data made by that same
simulator would pass even where the simulator's physics is wrong, so this module writes
"measured" runs from its own transcription of the same physics (DESIGN.md section 3,
docs/simhw.md sections 2-4). It imports nothing from ``fbs``, and it differs on purpose in:

* realization: one continuous state space per run, written here; the compensation network
  in parallel (partial-fraction, diagonal) form, the second-order filters with scaled states,
  angles in microradians;
* integrator: the bilinear (Tustin) transform (``scipy.signal.cont2discrete``) at an internal
  rate of at least 8 x the output rate (and 8 kHz), run by a dense numba loop;
* noise synthesis: whole-record FFT shaping of white Gaussian noise to the target PSD (the
  1/f part exact down to 1/T), pickoff lines from ``numpy.sin`` of the time vector, offset
  jumps from exponential (Poisson) switching times.

Only one platform axis is modelled (Mode 3, autocollimator control, gyro caged by its own
pickoff). Its four recorded channels are written: ``ac_{a}_ctl``, ``ac_{a}_inst``,
``gyro_{a}``, ``pa_{a}`` (a = x or y), in volts, in the "fbs-run" layout of DESIGN.md
section 6 (plain h5py). Not modelled: gyro cross-axis coupling (so no
``gyro_cross_coupling``), random gyro drift, the other axes, sensor ranges and Dahl
hysteresis (the bearing is a linear spring); the one nonlinearity is the opt-in power
amplifier dead zone / limit below.

Every keyword below defaults to the data sheet (or to "absent"); at the defaults a run is
sample for sample the run this module wrote before they existed (same random draws in the
same order), so a test's seed keeps its meaning. One exception: the gyro pickoff's data-sheet
noise follows DESIGN.md section 3 as revised (the lines carry 85 % of the variance, see
:data:`PICKOFF_LINES_URAD`), so the gyro channel's samples changed then; the pickoff does not
enter the platform loop, and the other three channels did not.

**Effects of the catalogue** (DESIGN.md section 8; 0 = absent; any combination may be given
at once, they act on different parts of the loop):

* ``stiffness_Nm_per_rad``: ``bearing_friction`` as its small-motion spring eta To^2 (Ch. V F).
* ``mount_freq_hz``, ``mount_damping``, ``mount_excitation``: ``mount_resonance``, the sensed
  angle through a second-order mount mode (Ch. II B.9, III B),
  th_b'' + 2 zeta w th_b' + w^2 th_b = w^2 th + a. ``a`` is the floor's white angular
  acceleration on the mount (DESIGN.md section 8: how strongly the mount is shaken is part
  of the effect), sized so that the undisturbed mount's (th = 0) peak PSD of th_b is
  ``mount_excitation`` times this unit's white autocollimator angle PSD (0 = only the loop
  moves the mount, as before the keyword existed).
* ``pickup``: ``pickup_line``, sinusoids (Hz, V) on the recorded control channel (Ch. V D-E).
* ``flicker_corner_hz``: ``flicker_noise`` (Ch. V B.3): the autocollimator's 1/f corner is this
  instead of the unit's own (the 1/f meets this unit's white level there); the knee's form and
  the slope stay the unit's (as the gapdata set's simulator does). :func:`draw_effect` uses it.
* ``extra_flicker_corner_hz`` (older form, kept for old callers): extra 1/f autocollimator
  noise, ``S_w a_w^2 c / f`` added to the unit's noise, i.e. a pure 1/f meeting this unit's
  white level at ``c`` (with the default sum knee and slope 1 the corners add).
* ``offset_jump_urad``, ``offset_jump_interval_s``: ``offset_jumps``, a +-A telegraph on the
  sensed angle at Poisson times (Ch. II B.10).
* ``extra_damping_Nms``: ``extra_damping``, viscous gimbal damping added to D (Ch. V F).
* ``scale_factor_error``: ``scale_factor_error``, the control and instrumentation channels'
  scale factors (Table 1) times ``1 + fraction``; the control channel is in the loop, so the
  loop gain changes with it.
* ``time_delay_s``: ``time_delay``, a pure delay of the sensed angle ahead of both
  autocollimator filters, exact (a delay line at the internal step 1/(8 x rate), to which it
  is rounded; not a Pade approximant).

**Unit-to-unit variation** (nuisance: what differs between two rigs built to the same data
sheet and is no effect; :func:`draw_nuisance` draws DESIGN.md section 8's envelope of a
nominal unit, :data:`NUISANCE_RANGES`):

* ``ac_white_scale`` (x0.6-1.6): the autocollimator's white (dark-current shot noise) rms
  relative to the data sheet's NEA (0.451 / 0.506 urad in 0.1-100 Hz, DESIGN.md section 3,
  Table 1); its PSD ``S_w a_w^2`` scales by the square, and the 1/f with it.
* ``ac_flicker_corner_hz`` (1.5-5 Hz; data sheet 3), ``ac_knee`` (0-1; data sheet 1) and
  ``ac_flicker_slope`` (0.8-1.2; data sheet 1): the autocollimator's 1/f noise, DESIGN.md
  section 3 "1/f below ~3 Hz" (Ch. II B: flicker noise of the photodetector). The sensor PSD
  is ``S_w a_w^2 K(f)`` with ``r = (f_c / f)^a`` and
  ``K = knee (1 + r) + (1 - knee) max(1, r)``: knee 1 is the smooth sum ``1 + (f_c/f)^a``,
  knee 0 the sharp ``max(1, (f_c/f)^a)``, between them their mix. ``f_c`` is the unit's own
  corner, where the 1/f meets the unit's white level.
* ``ac_flicker_scale`` (older form, default None; not drawn any more): given a number
  ``a_f``, the 1/f has the old meaning, independent of the white: its level is
  ``S_w a_f^2 f_c / f`` (``f_c`` where it meets the *data sheet's* white), so the unit's own
  corner is ``a_f^2 f_c / a_w^2`` (the old sensor PSD ``S_w (a_w^2 + a_f^2 f_c / f)`` exactly,
  with the default knee and slope).
* ``pickoff_white_scale`` (x0.5-2): the gyro pickoff's white noise rms relative to the data
  sheet's (:func:`white_level_pickoff`: 15 % of the variance of 6.2 / 12.4 urad rms in
  0.1-200 Hz, DESIGN.md section 3, Table 4).
* ``pickoff_line_freqs_hz``, ``pickoff_line_scales``: the pickoff's discrete lines
  (:data:`PICKOFF_LINES_URAD`, per axis) moved to these frequencies and their amplitudes times
  these factors, one per data-sheet line (None = the data sheet's). :func:`draw_nuisance` moves
  the whole set by up to +-0.8 Hz together, 102 and 187 Hz by a further +-0.2 Hz each, the
  71 Hz pair's spacing to 0.7-0.9 Hz (each line within +-1 Hz), and scales each amplitude by
  x0.5-2: another gyro's spin-motor and excitation harmonics sit a fraction of a hertz
  elsewhere.
* ``pickoff_lines`` (older form): the lines themselves, ``[(freq_hz, amplitude_urad), ...]``,
  replacing the data sheet's (not together with the two keywords above).
* ``adc_range_V``: the converter range (+-V; 16 bits), one number for all four channels or a
  mapping by channel name or by kind (``ctl``, ``inst``, ``gyro``, ``pa``); it sets the ADC
  floor q^2/(6 fs) (App. A.5). Default +-10 V everywhere; :func:`draw_nuisance` picks a lab's
  choice: ``ctl``, ``inst``, ``gyro`` from 1, 2, 5, 10 V and ``pa`` from 0.05, 0.1, 0.2, 0.5 V.

**Beyond the catalogue** (physics no catalogue entry describes; for the workflow's
"unexplained" verdict):

* ``amp_dead_zone_V``, ``amp_limit_V`` (a nonlinearity): the platform power amplifier (Ch. III
  C: gain Kp, a Minuteman I control amplifier's power stage) with a crossover dead zone of
  +-``amp_dead_zone_V`` at its output (the motor voltage) and/or an output limit of
  +-``amp_limit_V``: a push-pull stage whose quiescent bias has drifted. In Mode 3 the motor
  voltage is only tens of millivolts rms (V_c of about 0.2 mV times Kp 302 / 164), so a dead
  band of that size takes a large share of the loop gain at small signals, and how much
  depends on the signal's own level - no fixed linear change does that. The bench
  (``bench/gap_holdout.py``) uses 15-40 mV.
* ``comp_zeros_rad_s``, ``comp_poles_rad_s`` (a loop change): the compensation network's
  break frequencies (eq. 3.28: zeros 10, 30; poles 0.15, 200, 1200, 5000 rad/s; C(0) = 1
  kept). The network is passive (Ch. III E); the thesis found its measured transfer function
  within a factor of two of the design (Ch. V D, Fig. 40), so a break frequency off by x2 (a
  wrong or aged capacitor) is a rig one may meet. No catalogue entry moves a break frequency
  of the compensation: it reshapes the loop's phase lead, not its gain, delay or damping.
* ``amp_gain_factor``: the power amplifier's gain Kp times this factor. Note: in the spectra
  this is nearly a ``scale_factor_error`` with the sensor noise level rescaled (both change
  only the loop gain once the readout scale is taken by the noise level), so it is no test
  of "unexplained"; it is here for loop-gain experiments.

Usage from a test (pytest runs with ``--import-mode=importlib``): the ``independent`` fixture
of ``tests/procedures/analysis/gap/conftest.py`` returns this module::

    def test_something(independent, tmp_path):
        path = independent.generate(tmp_path / "run.h5", stiffness_Nm_per_rad=410.0, seed=3)

or load it by path with :func:`importlib.util.spec_from_file_location`.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import sys
from pathlib import Path
from typing import Any

import h5py
import numba
import numpy as np
import scipy.fft
import scipy.integrate
import scipy.signal

__all__ = [
    "ADC_LSB_V",
    "AXES",
    "MODULE_NAME",
    "NUISANCE_RANGES",
    "PICKOFF_LINES_URAD",
    "ac_noise_psd",
    "anti_alias_sos",
    "axis_model",
    "channel_names",
    "continuous_model",
    "draw_nuisance",
    "generate",
    "simulate",
    "unit_pickoff_lines",
    "white_level_ac",
    "white_level_pickoff",
]

# --------------------------------------------------------------------------- parameters
# Thesis values (Klinger 1974; DESIGN.md section 3). Angles in urad, rates in urad/s.
EARTH_RATE = 7.292115e-5  # rad/s
LATITUDE_DEG = 37.43
MOTOR = dict(Km=0.53, Kb=0.53, Ra=23.0, La=0.023)
COMP_ZEROS = (10.0, 30.0)  # rad/s, eq. 3.28 numerator
COMP_POLES = (0.15, 200.0, 1200.0, 5000.0)  # rad/s, eq. 3.28 denominator
AC_CTL = dict(w=264.0, zeta=0.71)
AC_INST = dict(w1=755.0, w2=1250.0, zeta=0.71)
AC_FLICKER_CORNER_HZ = 3.0
NEA_BAND_HZ = (0.1, 100.0)
PICKOFF_BAND_HZ = (0.1, 200.0)
#: DESIGN.md section 3: the pickoff's lines carry 85 % of the variance of its rms (6.2 / 12.4 urad,
#: X / Y), split 30/30/25/15 % over the 71 Hz pair (0.8 Hz apart), 102 and 187 Hz; the white
#: noise holds the rest (:func:`white_level_pickoff`).
PICKOFF_LINE_FREQS_HZ = (70.6, 71.4, 102.0, 187.0)
PICKOFF_LINE_SHARES = (0.30, 0.30, 0.25, 0.15)
PICKOFF_LINES_FRACTION = 0.85
PICKOFF_RMS_URAD = {"X": 6.2, "Y": 12.4}
#: The data sheet's lines per axis, ``(freq_hz, amplitude_urad)``: amplitude
#: sqrt(2 share 0.85 rms^2) (X 4.43, 4.43, 4.04, 3.13 urad; Y twice that).
PICKOFF_LINES_URAD = {
    ax: tuple(
        (f, math.sqrt(2.0 * share * PICKOFF_LINES_FRACTION * rms**2))
        for f, share in zip(PICKOFF_LINE_FREQS_HZ, PICKOFF_LINE_SHARES)
    )
    for ax, rms in PICKOFF_RMS_URAD.items()
}
SENSE_OHM = 92.1
KTC_A_PER_V = -6.04e-3
CAGING_WN, CAGING_ZETA = 0.1, 0.7
ADC_BITS, ADC_RANGE_V = 16, 10.0
ADC_LSB_V = 2 * ADC_RANGE_V / 2**ADC_BITS
ANTI_ALIAS_FRACTION, ANTI_ALIAS_POLES = 0.3, 3

AXES = {
    # I kg m^2, D N m s (2 Do on X, Do on Y), Kp, autocollimator mV/urad, NEA urad,
    # gyro channel: h/k s, KTO urad/s/V, Kg mV/urad, pickoff rms urad, constant rate urad/s
    "X": dict(
        I=0.70,
        D=1.02,
        Kp=302.0,
        K_ctl=5.70,
        K_inst=5.63,
        nea=0.451,
        tau_r=424.0,
        KTO=31.6,
        Kg=6.03,
        pickoff_rms=PICKOFF_RMS_URAD["X"],
        omega_const=(EARTH_RATE * math.cos(math.radians(LATITUDE_DEG))) * 1e6 + 0.35,
    ),
    "Y": dict(
        I=0.25,
        D=0.51,
        Kp=164.0,
        K_ctl=5.99,
        K_inst=5.92,
        nea=0.506,
        tau_r=708.0,
        KTO=33.4,
        Kg=6.70,
        pickoff_rms=PICKOFF_RMS_URAD["Y"],
        omega_const=-0.22,
    ),
}
#: Output order of the state-space model (and of the channels written).
OUTPUTS = ("ctl", "inst", "gyro", "pa")


def channel_names(axis: str) -> tuple[str, ...]:
    a = axis.lower()
    return (f"ac_{a}_ctl", f"ac_{a}_inst", f"gyro_{a}", f"pa_{a}")


def axis_model(axis: str) -> dict:
    if axis not in AXES:
        raise ValueError(f"axis {axis!r}: the generator models X or Y")
    return dict(AXES[axis])


# --------------------------------------------------------------------------- continuous model
def _compensation_residues(zeros=COMP_ZEROS, poles=COMP_POLES) -> np.ndarray:
    """C(s) = sum_j r_j / (s + p_j): residues of eq. 3.28 at its four distinct real poles."""
    z1, z2 = zeros
    p = np.array(poles, dtype=float)
    if p.shape != (4,) or len(set(p.tolist())) != 4 or np.any(p <= 0) or min(zeros) <= 0:
        raise ValueError(
            f"compensation: two positive zeros and four distinct positive poles, not {zeros}, {poles}"
        )
    gain = np.prod(p) / (z1 * z2)  # C(s) = gain (s + z1)(s + z2) / prod(s + p_j)
    r = np.empty(4)
    for j in range(4):
        others = np.prod([p[i] - p[j] for i in range(4) if i != j])
        r[j] = gain * (z1 - p[j]) * (z2 - p[j]) / others
    return r


def caging_gains(m: dict) -> tuple[float, float]:
    """C1 (V/V), C2 (1/s) of the PI caging amplifier, from omega_n^2 = K_T K_g C2 and
    2 zeta omega_n = K_T K_g C1, K_T = 92.1 ohm x KTO x KTC (urad/s per V of V_F).
    K_T is negative (KTC < 0), so both gains come out negative: that is what makes the loop
    s^2 + (2 zeta wn + k/h) s + wn^2 stable with V_F = -(C1 e + C2 int e)."""
    kt = SENSE_OHM * m["KTO"] * KTC_A_PER_V  # urad/s per V
    kg = m["Kg"] * 1e-3  # V per urad
    return 2 * CAGING_ZETA * CAGING_WN / (kt * kg), CAGING_WN**2 / (kt * kg)


def continuous_model(
    axis: str = "X",
    stiffness_Nm_per_rad: float = 0.0,
    mount_freq_hz: float = 0.0,
    mount_damping: float = 0.05,
    *,
    extra_damping_Nms: float = 0.0,
    scale_factor_error: float = 0.0,
    comp_zeros_rad_s=None,
    comp_poles_rad_s=None,
    amp_gain_factor: float = 1.0,
    amp_input: bool = False,
    delayed_sensor: bool = False,
    mount_input: bool = False,
):
    """(A, B, C, D, x0, names) of one axis in Mode 3.

    Inputs: autocollimator angle noise n_ac (urad), pickoff angle noise n_p (urad), constant
    gyro input rate Omega (urad/s). Outputs (V): control channel, instrumentation channel,
    gyro pickoff, power-amplifier input V_c. ``x0`` is the steady state for the constant
    Omega (caging integrator holding it), with all outputs zero there.

    ``mount_input`` (with a mount mode) adds an input column, the angular acceleration ``a``
    shaking the mount (urad/s^2: th_b'' + 2 zeta w th_b' + w^2 th_b = w^2 th + a).

    Opened for the elements :func:`simulate` runs outside the linear model (the states stay
    the same, in the same order): ``amp_input`` cuts the power amplifier out, its output
    voltage (V, at the motor) becomes an extra input column; ``delayed_sensor`` feeds both
    autocollimator filters from an extra input column, the delayed sensed angle (urad), and
    adds the sensed angle (theta_m + n_ac, urad) as an extra output row. Extra columns
    follow Omega in the order mount acceleration, amplifier output, delayed sensed angle;
    the extra row follows V_c.
    """
    m = axis_model(axis)
    zeros = COMP_ZEROS if comp_zeros_rad_s is None else tuple(float(z) for z in comp_zeros_rad_s)
    poles = COMP_POLES if comp_poles_rad_s is None else tuple(float(p) for p in comp_poles_rad_s)
    names: list[str] = []

    def st(name):
        names.append(name)
        return len(names) - 1

    th, om, cur = st("theta"), st("omega"), st("i")
    comp = [st(f"c{j}") for j in range(4)]
    mount = (st("mount1"), st("mount2")) if mount_freq_hz > 0 else None
    a1, a2 = st("ctl1"), st("ctl2")
    b0, b1, b2 = st("inst0"), st("inst1"), st("inst2")
    sg, q = st("sigma"), st("cage_int")
    n = len(names)
    NAC, NP, OM = 0, 1, 2
    n_in = 3
    VAMP = SD = MNT = -1
    if mount_input:
        if mount is None:
            raise ValueError("mount_input needs a mount mode (mount_freq_hz > 0)")
        MNT, n_in = n_in, n_in + 1
    if amp_input:
        VAMP, n_in = n_in, n_in + 1
    if delayed_sensor:
        SD, n_in = n_in, n_in + 1
    n_out = 5 if delayed_sensor else 4
    A, B = np.zeros((n, n)), np.zeros((n, n_in))
    C, D = np.zeros((n_out, n)), np.zeros((n_out, n_in))

    # Sensed angle s = theta_m + n_ac (urad), as a row over (x, u).
    s_x, s_u = np.zeros(n), np.zeros(n_in)
    s_u[NAC] = 1.0
    if mount is None:
        s_x[th] = 1.0
    else:  # theta_m = w^2/(s^2 + 2 zeta w s + w^2) theta, scaled states
        w = 2 * math.pi * mount_freq_hz
        m1, m2 = mount
        A[m1, m2] = w
        A[m2, th], A[m2, m1], A[m2, m2] = w, -w, -2 * mount_damping * w
        if mount_input:
            B[m2, MNT] = 1.0 / w  # mount1'' = w mount2' gets the acceleration
        s_x[m1] = 1.0
    # What the filters see: the sensed angle, or (delayed_sensor) the input column SD.
    f_x, f_u = s_x, s_u
    if delayed_sensor:
        f_x, f_u = np.zeros(n), np.zeros(n_in)
        f_u[SD] = 1.0
    # Control filter (eq. 3.21): a1 = w^2/(s^2 + 2 zeta w s + w^2) s.
    w, z = AC_CTL["w"], AC_CTL["zeta"]
    A[a1, a2] = w
    A[a2] += w * f_x
    B[a2] += w * f_u
    A[a2, a1] += -w
    A[a2, a2] += -2 * z * w
    gamma = np.zeros(n)
    gamma[a1] = m["K_ctl"] * (1.0 + scale_factor_error) * 1e-3  # V
    # Instrumentation (eq. 3.22): w1/(s + w1) then w2^2/(s^2 + 2 zeta w2 s + w2^2).
    w1, w2, z2 = AC_INST["w1"], AC_INST["w2"], AC_INST["zeta"]
    A[b0] += w1 * f_x
    B[b0] += w1 * f_u
    A[b0, b0] += -w1
    A[b1, b2] = w2
    A[b2, b0], A[b2, b1], A[b2, b2] = w2, -w2, -2 * z2 * w2
    # Compensation, parallel form, driven by gamma; V_c = -C(s) gamma (inverted).
    r = _compensation_residues(zeros, poles)
    vc = np.zeros(n)
    for j, cj in enumerate(comp):
        A[cj] += gamma
        A[cj, cj] += -poles[j]
        vc[cj] = -r[j]
    # Motor: La i' = Kp V_c - Kb theta' - Ra i  (theta' in urad/s -> 1e-6).
    La = MOTOR["La"]
    if amp_input:
        B[cur, VAMP] = 1.0 / La
    else:
        A[cur] += m["Kp"] * amp_gain_factor * vc / La
    A[cur, om] += -MOTOR["Kb"] * 1e-6 / La
    A[cur, cur] += -MOTOR["Ra"] / La
    # Gimbal: I theta'' = Km i - D theta' - k theta  (urad units: torque x 1e6).
    A[th, om] = 1.0
    A[om, cur] = MOTOR["Km"] * 1e6 / m["I"]
    A[om, om] = -(m["D"] + extra_damping_Nms) / m["I"]
    A[om, th] = -stiffness_Nm_per_rad / m["I"]
    # Gyro channel: sigma' = theta' + Omega + KTO V_T - sigma/(h/k); e = Kg (sigma + n_p);
    # V_F = -(C1 e + C2 int e); V_T = 92.1 KTC V_F.
    c1, c2 = caging_gains(m)
    kg = m["Kg"] * 1e-3
    kt = SENSE_OHM * m["KTO"] * KTC_A_PER_V
    A[q, sg] = kg
    B[q, NP] = kg
    A[sg, om] = 1.0
    B[sg, OM] = 1.0
    A[sg, sg] = -1.0 / m["tau_r"] - kt * c1 * kg
    B[sg, NP] = -kt * c1 * kg
    A[sg, q] = -kt * c2
    # Outputs.
    C[0] = gamma
    C[1, b1] = m["K_inst"] * (1.0 + scale_factor_error) * 1e-3
    C[2, sg] = kg
    D[2, NP] = kg
    C[3] = vc
    if delayed_sensor:
        C[4], D[4] = s_x, s_u
    x0 = np.zeros(n)
    x0[q] = m["omega_const"] / (kt * c2)  # caged: K_T V_F = -Omega, sigma = 0
    return A, B, C, D, x0, names


def white_level_ac(axis: str = "X") -> float:
    """S_w (urad^2/Hz, one-sided): int_0.1^100 S_w (1 + 3/f) |H_ctl|^2 df = NEA^2."""
    w, z = AC_CTL["w"], AC_CTL["zeta"]

    def integrand(u):  # over u = ln f
        f = math.exp(u)
        x = 2 * math.pi * f / w
        h2 = 1.0 / ((1 - x * x) ** 2 + (2 * z * x) ** 2)
        return (f + AC_FLICKER_CORNER_HZ) * h2

    val, _ = scipy.integrate.quad(
        integrand,
        math.log(NEA_BAND_HZ[0]),
        math.log(NEA_BAND_HZ[1]),
        epsabs=0,
        epsrel=1e-10,
        limit=200,
    )
    return axis_model(axis)["nea"] ** 2 / val


def white_level_pickoff(axis: str = "X") -> float:
    """White pickoff PSD (urad^2/Hz) that with the axis's data-sheet lines gives the rms in
    0.1-200 Hz: 15 % of the variance (X 0.0288, Y 0.115 urad^2/Hz: 1.7 / 3.4 urad in 0.1-100 Hz)."""
    m = axis_model(axis)
    lines_var = sum(
        a * a / 2
        for f, a in PICKOFF_LINES_URAD[axis]
        if PICKOFF_BAND_HZ[0] <= f <= PICKOFF_BAND_HZ[1]
    )
    return (m["pickoff_rms"] ** 2 - lines_var) / (PICKOFF_BAND_HZ[1] - PICKOFF_BAND_HZ[0])


def anti_alias_sos(rate_hz: float, fs_int: float) -> np.ndarray:
    return scipy.signal.butter(
        ANTI_ALIAS_POLES, ANTI_ALIAS_FRACTION * rate_hz, fs=fs_int, output="sos"
    )


# --------------------------------------------------------------------------- time stepping
#: The name the tests' conftest registers this module under (``sys.modules``). numba's on-disk
#: cache re-imports the defining module by name, so it is used only under this name; loaded
#: any other way the kernel compiles afresh (about 1 s per process).
MODULE_NAME = "fbs_tests_gap_independent"
_CACHE = __name__ == MODULE_NAME and __name__ in sys.modules


@numba.njit(cache=_CACHE, nogil=True)
def _tustin_run(Ad, Bd, Cd, Dd, bconst, dconst, x, u, y):
    """y[k] = Cd x + Dd u[k] + dconst;  x <- Ad x + Bd u[k] + bconst (dense)."""
    n = x.shape[0]
    m = u.shape[1]
    p = Cd.shape[0]
    xn = np.empty(n)
    for k in range(u.shape[0]):
        for i in range(p):
            acc = dconst[i]
            for j in range(n):
                acc += Cd[i, j] * x[j]
            for j in range(m):
                acc += Dd[i, j] * u[k, j]
            y[k, i] = acc
        for i in range(n):
            acc = bconst[i]
            for j in range(n):
                acc += Ad[i, j] * x[j]
            for j in range(m):
                acc += Bd[i, j] * u[k, j]
            xn[i] = acc
        for i in range(n):
            x[i] = xn[i]


def _shaped_noise(rng: np.random.Generator, n: int, fs: float, psd) -> np.ndarray:
    """n samples whose one-sided PSD is psd(f) (f > 0; zero mean), by shaping the FFT of
    white Gaussian noise over the whole record (periodic; exact down to 1/T)."""
    spec = scipy.fft.rfft(rng.standard_normal(n))
    f = np.arange(len(spec)) * (fs / n)
    gain = np.zeros(len(spec))
    gain[1:] = np.sqrt(psd(f[1:]) * fs / 2.0)  # a unit-variance sequence has PSD 2/fs
    return scipy.fft.irfft(spec * gain, n=n)


def _telegraph(
    rng: np.random.Generator, n: int, fs: float, amplitude: float, mean_interval_s: float
) -> np.ndarray:
    """+-amplitude, switching sign at Poisson times of mean interval ``mean_interval_s``."""
    t_end = n / fs
    times = []
    t = 0.0
    while True:
        t += rng.exponential(mean_interval_s)
        if t >= t_end:
            break
        times.append(t)
    start = 1.0 if rng.random() < 0.5 else -1.0
    flips = np.searchsorted(np.asarray(times) * fs, np.arange(n), side="right")
    return amplitude * start * np.where(flips % 2 == 0, 1.0, -1.0)


def _settle_time(A: np.ndarray, names: list[str]) -> float:
    """Time for the platform loop's slowest mode to decay by e^-10 (gyro modes excluded)."""
    keep = [i for i, s in enumerate(names) if s not in ("sigma", "cage_int")]
    ev = np.linalg.eigvals(A[np.ix_(keep, keep)])
    slowest = float(np.min(-ev.real))
    return min(max(10.0 / slowest, 2.0), 120.0)


# --------------------------------------------------------------------------- the generator
#: DESIGN.md section 8's tolerances of a nominal unit, as :func:`draw_nuisance` draws them (the
#: module docstring gives each one's meaning). Factors and the corner are drawn log-uniform
#: (:data:`NUISANCE_LOG_UNIFORM`), the rest uniform; the ADC ranges uniform among those listed.
NUISANCE_RANGES = dict(
    ac_white_scale=(0.6, 1.6),
    ac_knee=(0.0, 1.0),  # a third each: 0 (max), 1 (sum), uniform in between
    ac_flicker_corner_hz=(1.5, 5.0),
    ac_flicker_slope=(0.8, 1.2),
    pickoff_white_scale=(0.5, 2.0),
    line_shift_hz=(-1.0, 1.0),  # each line's move: the common shift and its own jitter
    line_common_shift_hz=(-0.8, 0.8),  # the whole set, the 71 Hz pair's centre with it
    line_jitter_hz=(-0.2, 0.2),  # 102 and 187 Hz each, beyond the common shift
    pair_spacing_hz=(0.7, 0.9),  # the 71 Hz pair stays a pair
    line_amplitude_scale=(0.5, 2.0),
    adc_range_V={
        "ctl": (1.0, 2.0, 5.0, 10.0),
        "inst": (1.0, 2.0, 5.0, 10.0),
        "gyro": (1.0, 2.0, 5.0, 10.0),
        "pa": (0.05, 0.1, 0.2, 0.5),
    },
)
NUISANCE_LOG_UNIFORM = (
    "ac_white_scale",
    "ac_flicker_corner_hz",
    "pickoff_white_scale",
    "line_amplitude_scale",
)
_KINDS = ("ctl", "inst", "gyro", "pa")


def draw_nuisance(rng: np.random.Generator) -> dict:
    """Keywords of :func:`simulate` / :func:`generate` for one unit drawn at random within
    :data:`NUISANCE_RANGES` (DESIGN.md section 8's envelope). "Nominal with ordinary unit-to-unit
    variation": no effect is drawn. The same keywords serve both axes (the pickoff lines are
    given relative to the axis's data sheet).

    The draws keep the old order where a quantity kept its place: white, [the knee, where the
    old 1/f level was], corner, pickoff white, the lines' common shift (the old pair centre),
    the pair's spacing, the 102 / 187 Hz jitters, four amplitudes, four ADC ranges; then the
    slope (new, last)."""
    R = NUISANCE_RANGES

    def draw(key):
        lo, hi = R[key]
        if key in NUISANCE_LOG_UNIFORM:
            return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
        return float(rng.uniform(lo, hi))

    white = draw("ac_white_scale")
    u = float(rng.uniform(0.0, 1.0))
    knee = 0.0 if u < 1 / 3 else 1.0 if u < 2 / 3 else 3.0 * u - 2.0
    corner = draw("ac_flicker_corner_hz")
    pickoff_white = draw("pickoff_white_scale")
    shift = draw("line_common_shift_hz")
    spacing = draw("pair_spacing_hz")
    f_a, f_b = PICKOFF_LINE_FREQS_HZ[:2]
    centre = 0.5 * (f_a + f_b) + shift
    freqs = [centre - spacing / 2, centre + spacing / 2]
    freqs += [f + shift + draw("line_jitter_hz") for f in PICKOFF_LINE_FREQS_HZ[2:]]
    scales = [draw("line_amplitude_scale") for _ in PICKOFF_LINE_FREQS_HZ]
    adc = {k: float(rng.choice(R["adc_range_V"][k])) for k in _KINDS}
    slope = draw("ac_flicker_slope")
    return {
        "ac_white_scale": white,
        "ac_knee": knee,
        "ac_flicker_corner_hz": corner,
        "ac_flicker_slope": slope,
        "pickoff_white_scale": pickoff_white,
        "pickoff_line_freqs_hz": [round(f, 4) for f in freqs],
        "pickoff_line_scales": [round(a, 4) for a in scales],
        "adc_range_V": adc,
    }


def unit_pickoff_lines(
    axis: str = "X", pickoff_line_freqs_hz=None, pickoff_line_scales=None, pickoff_lines=None
) -> list[tuple[float, float]]:
    """The unit's pickoff lines ``[(freq_hz, amplitude_urad), ...]``: ``pickoff_lines`` if given,
    else the axis's data-sheet lines (:data:`PICKOFF_LINES_URAD`) moved to
    ``pickoff_line_freqs_hz`` and scaled by ``pickoff_line_scales`` (each one per line)."""
    axis = axis.upper()
    axis_model(axis)
    if pickoff_lines is not None:
        if pickoff_line_freqs_hz is not None or pickoff_line_scales is not None:
            raise ValueError(
                "pickoff_lines replaces the data sheet's lines: not together with "
                "pickoff_line_freqs_hz / pickoff_line_scales"
            )
        return [(float(f), float(a)) for f, a in pickoff_lines]
    sheet = PICKOFF_LINES_URAD[axis]
    freqs = (
        [f for f, _ in sheet]
        if pickoff_line_freqs_hz is None
        else [float(f) for f in pickoff_line_freqs_hz]
    )
    scales = (
        [1.0] * len(sheet)
        if pickoff_line_scales is None
        else [float(a) for a in pickoff_line_scales]
    )
    if len(freqs) != len(sheet) or len(scales) != len(sheet):
        raise ValueError(
            f"pickoff_line_freqs_hz / pickoff_line_scales: one per data-sheet line ({len(sheet)})"
        )
    if min(freqs) <= 0 or min(scales) < 0:
        raise ValueError(f"pickoff lines: frequencies > 0 and scales >= 0, not {freqs}, {scales}")
    return [(f, a * k) for f, (_, a), k in zip(freqs, sheet, scales)]


def ac_noise_psd(
    f,
    axis: str = "X",
    *,
    ac_white_scale=1.0,
    ac_flicker_scale=None,
    ac_flicker_corner_hz=AC_FLICKER_CORNER_HZ,
    ac_knee=1.0,
    ac_flicker_slope=1.0,
    flicker_corner_hz=0.0,
    extra_flicker_corner_hz=0.0,
) -> np.ndarray:
    """One-sided PSD (urad^2/Hz) of the autocollimator angle noise at ``f`` (> 0):
    ``S_w (a_w^2 K(f) + a_w^2 extra / f)``, ``K = knee (1 + r) + (1 - knee) max(1, r)``,
    ``r = (f_c / f)^a`` (the module docstring; ``f_c`` = ``flicker_corner_hz`` if given, else
    the unit's own corner). At the data sheet: ``S_w (1 + 3 / f)``."""
    for name, v in (
        ("ac_white_scale", ac_white_scale),
        ("ac_flicker_corner_hz", ac_flicker_corner_hz),
        ("flicker_corner_hz", flicker_corner_hz),
        ("extra_flicker_corner_hz", extra_flicker_corner_hz),
    ):
        if not (v >= 0 and math.isfinite(v)):
            raise ValueError(f"{name} must be finite and >= 0, not {v!r}")
    if ac_flicker_scale is not None and not (
        ac_flicker_scale >= 0 and math.isfinite(ac_flicker_scale)
    ):
        raise ValueError(
            f"ac_flicker_scale must be None or finite and >= 0, not {ac_flicker_scale!r}"
        )
    if not 0.0 <= ac_knee <= 1.0:
        raise ValueError(f"ac_knee must be within 0 (max form) .. 1 (sum form), not {ac_knee!r}")
    if not (ac_flicker_slope > 0 and math.isfinite(ac_flicker_slope)):
        raise ValueError(f"ac_flicker_slope must be finite and > 0, not {ac_flicker_slope!r}")
    f = np.asarray(f, dtype=float)
    sw = white_level_ac(axis)
    white = ac_white_scale**2
    # The 1/f's level at 1 Hz in units of S_w (slope 1): where it meets the unit's white is the
    # unit's corner. The old ac_flicker_scale ties it to the data sheet's white instead.
    if flicker_corner_hz > 0:
        level = white * flicker_corner_hz
    elif ac_flicker_scale is None:
        level = white * ac_flicker_corner_hz
    else:
        level = ac_flicker_scale**2 * ac_flicker_corner_hz
    extra = white * extra_flicker_corner_hz
    if ac_knee == 1.0 and ac_flicker_slope == 1.0:  # the sum form, slope 1: the old expression
        return sw * (white + (level + extra) / f)
    if ac_flicker_slope == 1.0:
        flick = level / f
    elif white > 0:
        flick = white * ((level / white) / f) ** ac_flicker_slope
    elif level > 0:
        raise ValueError(
            "a 1/f slope other than 1 needs a white level to meet (ac_white_scale > 0)"
        )
    else:
        flick = np.zeros_like(f)
    k = ac_knee * (white + flick) + (1.0 - ac_knee) * np.maximum(white, flick)
    return sw * (k + extra / f)


def _adc_ranges(adc_range_V, axis: str) -> np.ndarray:
    """The four channels' ranges (V) from a number, or a mapping by channel name or kind."""
    names = channel_names(axis)
    if isinstance(adc_range_V, (int, float)):
        ranges = [float(adc_range_V)] * 4
    else:
        given = dict(adc_range_V)
        unknown = set(given) - set(names) - set(_KINDS)
        if unknown:
            raise ValueError(
                f"adc_range_V: unknown channel(s) {sorted(unknown)}; use {names} or {_KINDS}"
            )
        ranges = [float(given.get(c, given.get(k, ADC_RANGE_V))) for c, k in zip(names, _KINDS)]
    if min(ranges) <= 0:
        raise ValueError(f"adc_range_V must be positive, not {ranges}")
    return np.array(ranges)


@numba.njit(cache=_CACHE, nogil=True)
def _amp_out(v, dead_zone, limit):
    """The power stage's output for an ideal one of ``v``: dead zone +-dead_zone, then +-limit."""
    if v > dead_zone:
        v = v - dead_zone
    elif v < -dead_zone:
        v = v + dead_zone
    else:
        v = 0.0
    if v > limit:
        return limit
    if v < -limit:
        return -limit
    return v


@numba.njit(cache=_CACHE, nogil=True)
def _loop_run(
    Ad,
    Bd,
    Cd,
    Dd,
    bconst,
    dconst,
    x,
    u,
    y,
    col_amp,
    row_vc,
    kp,
    dead_zone,
    limit,
    col_sd,
    row_s,
    buf,
):
    """The Tustin loop of :func:`_tustin_run` with the elements outside the linear model.

    Inputs ``u[k]`` fill the first columns; column ``col_amp`` (if >= 0) is the power
    amplifier's output, ``_amp_out(kp V_c)`` with V_c = output row ``row_vc`` (its own
    feedthrough from that column, order dt^n, solved by fixed-point iteration); column
    ``col_sd`` (if >= 0) is output row ``row_s`` delayed by ``len(buf)`` steps (``buf``
    holds the last ones, oldest at ``k % len(buf)``). ``y`` takes the first outputs."""
    n = x.shape[0]
    m = Bd.shape[1]
    p = Cd.shape[0]
    m_ext = u.shape[1]
    nd = buf.shape[0]
    xn = np.empty(n)
    uk = np.zeros(m)
    yk = np.empty(p)
    for k in range(u.shape[0]):
        for j in range(m_ext):
            uk[j] = u[k, j]
        if col_sd >= 0:
            uk[col_sd] = buf[k % nd]
        if col_amp >= 0:
            uk[col_amp] = 0.0
        for i in range(p):
            acc = dconst[i]
            for j in range(n):
                acc += Cd[i, j] * x[j]
            for j in range(m):
                acc += Dd[i, j] * uk[j]
            yk[i] = acc
        if col_amp >= 0:
            a = yk[row_vc]
            g = Dd[row_vc, col_amp]
            v = 0.0
            for _ in range(4):
                v = _amp_out(kp * (a + g * v), dead_zone, limit)
            uk[col_amp] = v
            for i in range(p):
                yk[i] += Dd[i, col_amp] * v
        if col_sd >= 0:
            buf[k % nd] = yk[row_s]
        for i in range(y.shape[1]):
            y[k, i] = yk[i]
        for i in range(n):
            acc = bconst[i]
            for j in range(n):
                acc += Ad[i, j] * x[j]
            for j in range(m):
                acc += Bd[i, j] * uk[j]
            xn[i] = acc
        for i in range(n):
            x[i] = xn[i]


def simulate(
    *,
    axis="X",
    duration_s=300.0,
    rate_hz=1000.0,
    seed=0,
    stiffness_Nm_per_rad=0.0,
    mount_freq_hz=0.0,
    mount_damping=0.05,
    pickup=None,
    extra_flicker_corner_hz=0.0,
    offset_jump_urad=0.0,
    offset_jump_interval_s=60.0,
    extra_damping_Nms=0.0,
    scale_factor_error=0.0,
    time_delay_s=0.0,
    ac_white_scale=1.0,
    ac_flicker_scale=None,
    ac_flicker_corner_hz=AC_FLICKER_CORNER_HZ,
    ac_knee=1.0,
    ac_flicker_slope=1.0,
    flicker_corner_hz=0.0,
    mount_excitation=0.0,
    pickoff_white_scale=1.0,
    pickoff_lines=None,
    pickoff_line_freqs_hz=None,
    pickoff_line_scales=None,
    adc_range_V=ADC_RANGE_V,
    amp_dead_zone_V=0.0,
    amp_limit_V=math.inf,
    amp_gain_factor=1.0,
    comp_zeros_rad_s=None,
    comp_poles_rad_s=None,
) -> dict[str, np.ndarray]:
    """The recorded channels (volts, ADC-quantized) as a dict, without writing a file.
    Keywords: see the module docstring."""
    axis = axis.upper()
    m = axis_model(axis)
    if not (rate_hz > 0 and duration_s > 0):
        raise ValueError("rate_hz and duration_s must be positive")
    for name, v in (
        ("pickoff_white_scale", pickoff_white_scale),
        ("amp_gain_factor", amp_gain_factor),
        ("mount_excitation", mount_excitation),
    ):
        if not (v >= 0 and math.isfinite(v)):
            raise ValueError(f"{name} must be finite and >= 0, not {v!r}")
    if mount_excitation > 0 and not mount_freq_hz > 0:
        raise ValueError("mount_excitation shakes a mount mode: it needs mount_freq_hz > 0")
    if amp_dead_zone_V < 0 or not amp_limit_V > 0 or time_delay_s < 0:
        raise ValueError("amp_dead_zone_V and time_delay_s must be >= 0, amp_limit_V > 0")
    ac_noise = dict(
        ac_white_scale=ac_white_scale,
        ac_flicker_scale=ac_flicker_scale,
        ac_flicker_corner_hz=ac_flicker_corner_hz,
        ac_knee=ac_knee,
        ac_flicker_slope=ac_flicker_slope,
        flicker_corner_hz=flicker_corner_hz,
        extra_flicker_corner_hz=max(extra_flicker_corner_hz, 0.0),
    )
    ac_noise_psd(1.0, axis, **ac_noise)  # checks the keywords before the long part
    lines = unit_pickoff_lines(axis, pickoff_line_freqs_hz, pickoff_line_scales, pickoff_lines)
    mount_in = mount_excitation > 0
    ranges = _adc_ranges(adc_range_V, axis)
    n_out = int(round(duration_s * rate_hz))
    over = max(8, int(math.ceil(8000.0 / rate_hz)))
    fs = rate_hz * over
    dt = 1.0 / fs
    n_delay = int(round(time_delay_s * fs))
    if time_delay_s > 0 and n_delay < 1:
        raise ValueError(f"time_delay_s {time_delay_s} is below the internal step {dt:.3g} s")
    nonlinear_amp = amp_dead_zone_V > 0 or math.isfinite(amp_limit_V)
    loop = dict(
        extra_damping_Nms=extra_damping_Nms,
        scale_factor_error=scale_factor_error,
        comp_zeros_rad_s=comp_zeros_rad_s,
        comp_poles_rad_s=comp_poles_rad_s,
        amp_gain_factor=amp_gain_factor,
    )

    A, B, C, D, x0, names = continuous_model(
        axis, stiffness_Nm_per_rad, mount_freq_hz, mount_damping, mount_input=mount_in, **loop
    )
    if np.max(np.linalg.eigvals(A).real) >= 0:
        raise ValueError(
            f"the loop is unstable with these settings ({loop}): no steady run to record"
        )
    settle_out = int(math.ceil(_settle_time(A, names) * rate_hz))
    n_run = (n_out + settle_out) * over
    n_fft = scipy.fft.next_fast_len(n_run, real=True)

    ss = np.random.SeedSequence(seed)
    # spawn(5)'s first four are spawn(4)'s: the old streams keep their draws
    rng_ac, rng_jump, rng_p, rng_lines, rng_mount = (
        np.random.Generator(np.random.PCG64(s)) for s in ss.spawn(5)
    )

    # Autocollimator angle noise (urad): S_w a_w^2 K(f) (ac_noise_psd), plus offset jumps. At
    # the data sheet (a_w = 1, f_c = 3, sum knee, slope 1) this is S_w (1 + (3 + extra)/f).
    u = np.empty((n_run, 3 if mount_in else 2))
    u[:, 0] = _shaped_noise(rng_ac, n_fft, fs, lambda f: ac_noise_psd(f, axis, **ac_noise))[:n_run]
    # The sensor's offset at the start: the slow part of the noise (a 0.2 s mean, which
    # leaves out the white part) plus the telegraph's level.
    offset0 = float(np.mean(u[: int(0.2 * fs), 0]))
    if offset_jump_urad > 0:
        tele = _telegraph(rng_jump, n_run, fs, offset_jump_urad, offset_jump_interval_s)
        u[:, 0] += tele
        offset0 += float(tele[0])
    # Pickoff noise (urad): white plus lines with random phases.
    sp = white_level_pickoff(axis)
    u[:, 1] = math.sqrt(sp * fs / 2.0) * pickoff_white_scale * rng_p.standard_normal(n_run)
    t = np.arange(n_run) * dt
    for f_line, amp in lines:
        phase = rng_lines.uniform(0.0, 2 * math.pi)
        if f_line < fs / 2:
            u[:, 1] += amp * np.sin(2 * math.pi * f_line * t + phase)
    if mount_in:
        # White angular acceleration on the mount (urad/s^2): |1/(s^2 + 2 zeta w s + w^2)|^2 peaks
        # at 1/(4 zeta^2 w^4 (1 - zeta^2)) (1/w^4 from zeta = 1/sqrt 2 up), so this PSD puts the
        # undisturbed mount's peak at mount_excitation x the unit's white sensor PSD.
        w, z = 2 * math.pi * mount_freq_hz, mount_damping
        peak_gain = 1.0 / (4 * z * z * w**4 * (1 - z * z)) if z * z < 0.5 else 1.0 / w**4
        s_acc = mount_excitation * white_level_ac(axis) * ac_white_scale**2 / peak_gain
        u[:, 2] = math.sqrt(s_acc * fs / 2.0) * rng_mount.standard_normal(n_run)

    # Start in the steady state for the sensor offset present at t = 0 (the telegraph level
    # and the slow 1/f wander), as on a rig that has been running: the platform already
    # follows it, so no acquisition transient (and no false offset step) opens the record.
    x = np.ascontiguousarray(x0 + np.linalg.solve(A, -B[:, 0] * offset0), dtype=float)
    y = np.empty((n_run, 4))
    # Input columns: n_ac, n_p, Omega (a constant), [mount acceleration], [amplifier], [delay].
    noise_cols = [0, 1, 3] if mount_in else [0, 1]
    if not (nonlinear_amp or n_delay):
        Ad, Bd, Cd, Dd, _ = scipy.signal.cont2discrete((A, B, C, D), dt, method="bilinear")
        bconst = np.ascontiguousarray(Bd[:, 2] * m["omega_const"])
        dconst = np.ascontiguousarray(Dd[:, 2] * m["omega_const"])
        _tustin_run(
            np.ascontiguousarray(Ad),
            np.ascontiguousarray(Bd[:, noise_cols]),
            np.ascontiguousarray(Cd),
            np.ascontiguousarray(Dd[:, noise_cols]),
            bconst,
            dconst,
            x,
            u,
            y,
        )
    else:
        # The same states, the amplifier and/or the sensor path opened (continuous_model); the
        # kernel closes them with the dead zone / limit and the delay line.
        Ao, Bo, Co, Do, _, names_o = continuous_model(
            axis,
            stiffness_Nm_per_rad,
            mount_freq_hz,
            mount_damping,
            amp_input=nonlinear_amp,
            delayed_sensor=bool(n_delay),
            mount_input=mount_in,
            **loop,
        )
        assert names_o == names
        Ad, Bd, Cd, Dd, _ = scipy.signal.cont2discrete((Ao, Bo, Co, Do), dt, method="bilinear")
        keep = [j for j in range(Bd.shape[1]) if j != 2]  # Omega enters as a constant
        col_amp = keep.index(len(noise_cols) + 1) if nonlinear_amp else -1
        col_sd = keep.index(Bd.shape[1] - 1) if n_delay else -1
        # The delay line starts full of the steady sensed angle (the Tustin state's steady
        # state is the continuous one, so the continuous output row applies).
        buf = np.zeros(max(n_delay, 1))
        if n_delay:
            buf[:] = float(Co[4] @ x) + offset0
        _loop_run(
            np.ascontiguousarray(Ad),
            np.ascontiguousarray(Bd[:, keep]),
            np.ascontiguousarray(Cd),
            np.ascontiguousarray(Dd[:, keep]),
            np.ascontiguousarray(Bd[:, 2] * m["omega_const"]),
            np.ascontiguousarray(Dd[:, 2] * m["omega_const"]),
            x,
            u,
            y,
            col_amp,
            3,
            m["Kp"] * amp_gain_factor,
            float(amp_dead_zone_V),
            float(amp_limit_V),
            col_sd,
            4,
            buf,
        )
    del u

    # Electrical pickup on the control channel, phase zero at the recording's t = 0.
    t_rec = t - settle_out * over * dt
    for f_line, amp in pickup or []:
        y[:, 0] += amp * np.sin(2 * math.pi * f_line * t_rec)
    # Recording chain: 3-pole Butterworth at 0.3 fs, decimation, 16-bit ADC (+-10 V unless
    # adc_range_V says otherwise).
    y = scipy.signal.sosfilt(anti_alias_sos(rate_hz, fs), y, axis=0)
    y = y[settle_out * over :: over][:n_out]
    lsb = 2 * ranges / 2**ADC_BITS
    code = np.clip(np.rint(y / lsb), -(2 ** (ADC_BITS - 1)), 2 ** (ADC_BITS - 1) - 1)
    volts = code * lsb
    return {name: np.ascontiguousarray(volts[:, i]) for i, name in enumerate(channel_names(axis))}


#: generate()'s keywords beyond the original ones, with their defaults (written to the file's
#: meta only when given otherwise, so an old call's file keeps its meta).
_NEW_DEFAULTS = dict(
    extra_damping_Nms=0.0,
    scale_factor_error=0.0,
    time_delay_s=0.0,
    ac_white_scale=1.0,
    ac_flicker_scale=None,
    ac_flicker_corner_hz=AC_FLICKER_CORNER_HZ,
    ac_knee=1.0,
    ac_flicker_slope=1.0,
    flicker_corner_hz=0.0,
    mount_excitation=0.0,
    pickoff_white_scale=1.0,
    pickoff_lines=None,
    pickoff_line_freqs_hz=None,
    pickoff_line_scales=None,
    adc_range_V=ADC_RANGE_V,
    amp_dead_zone_V=0.0,
    amp_limit_V=math.inf,
    amp_gain_factor=1.0,
    comp_zeros_rad_s=None,
    comp_poles_rad_s=None,
)


def generate(
    path,
    *,
    axis="X",
    duration_s=300.0,
    rate_hz=1000.0,
    seed=0,
    stiffness_Nm_per_rad=0.0,
    mount_freq_hz=0.0,
    mount_damping=0.05,
    pickup=None,
    extra_flicker_corner_hz=0.0,
    offset_jump_urad=0.0,
    offset_jump_interval_s=60.0,
    **more,
) -> Path:
    """Write a Mode-3 "fbs-run" file of one axis's four channels; return its path.

    ``pickup`` is a list of ``(freq_hz, amplitude_V)`` lines added to the control channel
    before the anti-alias filter. The other keywords are the effects of DESIGN.md section 8
    that act on one axis in Mode 3 (0 = absent); ``more`` takes the keywords of
    :func:`simulate` added later (further effects, unit-to-unit variation, effects beyond
    the catalogue: the module docstring), e.g. ``**draw_nuisance(rng)``.
    """
    unknown = set(more) - set(_NEW_DEFAULTS)
    if unknown:
        raise TypeError(f"generate() got unexpected keyword(s) {sorted(unknown)}")
    params = dict(
        axis=axis.upper(),
        duration_s=float(duration_s),
        rate_hz=float(rate_hz),
        seed=int(seed),
        stiffness_Nm_per_rad=float(stiffness_Nm_per_rad),
        mount_freq_hz=float(mount_freq_hz),
        mount_damping=float(mount_damping),
        pickup=[[float(f), float(a)] for f, a in (pickup or [])],
        extra_flicker_corner_hz=float(extra_flicker_corner_hz),
        offset_jump_urad=float(offset_jump_urad),
        offset_jump_interval_s=float(offset_jump_interval_s),
    )
    extra = {k: v for k, v in more.items() if not _same(v, _NEW_DEFAULTS[k])}
    data = simulate(**{**params, "pickup": [tuple(p) for p in params["pickup"]]}, **extra)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "fbs-run"
        f.attrs["format_version"] = 1
        f.attrs["created"] = (
            _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds").replace("+00:00", "Z")
        )
        f.attrs["rig"] = "independent-generator"
        f.attrs["mode"] = 3
        f.attrs["axis"] = params["axis"]
        f.attrs["status"] = "complete"
        g = f.create_group("channels")
        for name, v in data.items():
            ds = g.create_dataset(name, data=v.astype(np.float64))
            ds.attrs["units"] = "V"
            ds.attrs["sample_rate_hz"] = float(rate_hz)
        meta = f.create_group("meta")
        meta.attrs["generator"] = json.dumps(
            {
                "name": "tests/procedures/analysis/gap/independent.py",
                **params,
                **{k: _jsonable(v) for k, v in extra.items()},
            }
        )
    return path


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return float(a) == float(b)
    return False


def _jsonable(v):
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    return v


# --------------------------------------------------------------------------- hidden-effect draws
# The draws of the hold-out measures (bench/gap_holdout.py) and of the acceptance tests
# (test_unit_variation.py): catalogue effects in the ranges where this loop shows them,
# and effects no catalogue entry describes.
def _log_uniform(rng, lo, hi):
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _delay(rng):
    # rounded to the generator's internal step at 1 kHz (1/8000 s), so the truth is the delay run
    return round(float(rng.uniform(0.0025, 0.004)) * 8000) / 8000


#: Catalogue effects the generator shows: draw(rng) -> (generator keywords, truth in the catalogue's
#: parameter names). Ranges: where the loop shows the effect and the generator stays stable on
#: both axes (a 5 ms delay on Y is at the edge of stability).
def draw_effect(name: str, rng: np.random.Generator) -> tuple[dict[str, Any], dict[str, float]]:
    if name == "bearing_friction":  # DESIGN.md: eta To^2 = 410 (X) / 380 (Y) N m/rad
        k = round(float(rng.uniform(300.0, 900.0)), 1)
        return {"stiffness_Nm_per_rad": k}, {"stiffness_Nm_per_rad": k}
    if (
        name == "mount_resonance"
    ):  # shaken by the floor too: peak x3-30 the unit's white (DESIGN.md 8)
        f, z = round(float(rng.uniform(25.0, 80.0)), 2), round(float(rng.uniform(0.02, 0.06)), 4)
        e = round(_log_uniform(rng, 3.0, 30.0), 3)
        return (
            {"mount_freq_hz": f, "mount_damping": z, "mount_excitation": e},
            {"freq_hz": f, "damping": z, "excitation": e},
        )
    if name == "pickup_line":
        f, a = round(float(rng.uniform(30.0, 250.0)), 2), round(_log_uniform(rng, 0.002, 0.006), 5)
        return {"pickup": [(f, a)]}, {"freq_hz": f, "amplitude_V": a}
    if name == "flicker_noise":  # the unit's corner (1.5-5 Hz) replaced by one well above it
        c = round(float(rng.uniform(12.0, 30.0)), 2)
        return {"flicker_corner_hz": c}, {"corner_hz": c}
    if name == "offset_jumps":  # Ch. II B.10 saw ~100 urad every 40-400 s; smaller here
        a, t = round(float(rng.uniform(8.0, 20.0)), 2), round(float(rng.uniform(30.0, 60.0)), 1)
        return {"offset_jump_urad": a, "offset_jump_interval_s": t}, {
            "amplitude_urad": a,
            "interval_s": t,
        }
    if name == "extra_damping":  # the gyros give 1.02 (X) / 0.51 (Y) N m s
        d = round(float(rng.uniform(2.0, 5.0)), 3)
        return {"extra_damping_Nms": d}, {"damping_Nms": d}
    if name == "scale_factor_error":
        fr = round(float(rng.choice([-1.0, 1.0]) * rng.uniform(0.25, 0.45)), 4)
        return {"scale_factor_error": fr}, {"fraction": fr}
    if name == "time_delay":
        d = _delay(rng)
        return {"time_delay_s": d}, {"delay_s": d}
    raise ValueError(name)


HIDDEN_EFFECTS = (
    "bearing_friction",
    "mount_resonance",
    "pickup_line",
    "flicker_noise",
    "offset_jumps",
    "extra_damping",
    "scale_factor_error",
    "time_delay",
)
KEY_PARAM = {
    "bearing_friction": "stiffness_Nm_per_rad",
    "mount_resonance": "freq_hz",
    "pickup_line": "freq_hz",
    "flicker_noise": "corner_hz",
    "offset_jumps": "amplitude_urad",
    "extra_damping": "damping_Nms",
    "scale_factor_error": "fraction",
    "time_delay": "delay_s",
}
HIDDEN_PAIRS = (
    ("bearing_friction", "pickup_line"),
    ("mount_resonance", "offset_jumps"),
    ("bearing_friction", "flicker_noise"),
    ("time_delay", "pickup_line"),
    ("extra_damping", "offset_jumps"),
    ("scale_factor_error", "mount_resonance"),
)


def draw_outside(kind: str, rng: np.random.Generator) -> tuple[dict[str, Any], dict[str, float]]:
    """Effects no catalogue entry describes (the generator's docstring): the level and why.

    * ``dead_zone``: power-amplifier crossover dead zone of 15-40 mV at the motor. The motor
      voltage is ~57 / 38 mV rms (X / Y) in Mode 3, so the loop loses most of its small-signal
      gain: the control channel rises 20-30 dB below 5 Hz (the platform no longer follows the
      sensor noise) and falls above the loop's resonance.
    * ``lead_zero``: eq. 3.28's lead zero w_c3 = 30 rad/s at x0.45-0.55 (a lead resistor off by
      x2; the thesis measured the network within a factor of two): the 5.7 / 8.2 Hz loop mode
      moves to ~11 / 15 Hz and its damping rises (X: zeta 0.14 -> 0.4): -14 dB at 3-8 Hz.
    * ``lead_pole``: eq. 3.28's pole w_c4 = 200 rad/s at x1.8-2.2: more phase lead, the loop
      mode's damping up by half (X 0.14 -> 0.2, Y 0.20 -> 0.32) at the same frequency: -3 to
      -4 dB at the peak; the smallest departure of the three.
    """
    if kind == "dead_zone":
        v = round(float(rng.uniform(0.015, 0.040)), 4)
        return {"amp_dead_zone_V": v}, {"amp_dead_zone_V": v}
    if kind == "lead_zero":
        z = round(30.0 * float(rng.uniform(0.45, 0.55)), 3)
        return {"comp_zeros_rad_s": [10.0, z]}, {"w_c3_rad_s": z}
    if kind == "lead_pole":
        p = round(200.0 * float(rng.uniform(1.8, 2.2)), 2)
        return {"comp_poles_rad_s": [0.15, p, 1200.0, 5000.0]}, {"w_c4_rad_s": p}
    raise ValueError(kind)


OUTSIDE_KINDS = ("dead_zone", "lead_zero", "lead_pole")
