"""Dahl's bearing-friction model and its identification (procedures/analysis/dahl.py; thesis Ch. V F)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.integrate
import scipy.signal
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from procedures.analysis import dahl

FS = 200.0
F0 = 0.4


# ---------------------------------------------------------------------------- references
def ode_dahl(theta: np.ndarray, To: float, eta: float, T0: float = 0.0) -> np.ndarray:
    """Eq. 5.2 integrated numerically (solve_ivp, the angle as the independent variable) over
    each monotone piece of a sampled path: an integrator independent of dahl_torque's closed form."""
    out = np.empty(len(theta))
    out[0] = T0
    T = T0
    i = 0
    n = len(theta)
    while i < n - 1:
        d = np.sign(theta[i + 1] - theta[i])
        j = i + 1
        while j < n - 1 and np.sign(theta[j + 1] - theta[j]) == d:
            j += 1
        if d == 0:
            out[i + 1 : j + 1] = T
        else:
            sgn = 1.0 if d > 0 else -1.0
            sol = scipy.integrate.solve_ivp(
                lambda th, y, s=sgn: eta * (y - s * To) ** 2,
                (theta[i], theta[j]),
                [T],
                t_eval=theta[i + 1 : j + 1],
                rtol=1e-11,
                atol=1e-14,
                method="DOP853",
            )
            assert sol.success
            out[i + 1 : j + 1] = sol.y[0]
            T = float(sol.y[0, -1])
        i = j
    return out


def ladder(
    amplitudes_rad: list[float], cycles: int, fs: float = FS, f0: float = F0, lead_s: float = 0.0
):
    """theta = A_k sin(w t) with A stepping at zero crossings, each held ``cycles`` periods."""
    n_per = int(round(fs / f0))
    t = np.arange(n_per * cycles * len(amplitudes_rad)) / fs
    amp = np.repeat(amplitudes_rad, n_per * cycles)
    theta = amp * np.sin(2 * math.pi * f0 * t)
    lead = np.zeros(int(round(lead_s * fs)))
    return np.concatenate([lead, theta]), np.concatenate(
        [lead, -amp * np.sin(2 * math.pi * f0 * t)]
    )


# ---------------------------------------------------------------------------- the model
@settings(max_examples=12, deadline=None)
@given(
    To=st.floats(0.005, 0.05),
    eta_To=st.floats(2e3, 1e5),
    amp_urad=st.floats(2.0, 800.0),
    T0_frac=st.floats(-0.9, 0.9),
)
def test_closed_form_matches_an_ode_solver(To, eta_To, amp_urad, T0_frac):
    """dahl_torque (eq. 5.3 per monotone step) agrees with solve_ivp of eq. 5.2, whatever the
    step size, starting torque and amplitude (noise-like reversals included)."""
    eta = eta_To / To
    rng = np.random.default_rng(int(amp_urad * 1000) % 2**32)
    t = np.arange(300) / FS
    # a sine with noise-like reversals near its peaks and steps of every size
    theta = (
        amp_urad * 1e-6 * (np.sin(2 * math.pi * F0 * t * 5) + 0.02 * rng.standard_normal(len(t)))
    )
    got = dahl.dahl_torque(theta, To, eta, T0_frac * To)
    ref = ode_dahl(theta, To, eta, T0_frac * To)
    assert np.max(np.abs(got - ref)) < 1e-6 * To


@settings(max_examples=30, deadline=None)
@given(To=st.floats(1e-3, 0.1), eta=st.floats(1e4, 1e8), seed=st.integers(0, 2**32 - 1))
def test_torque_never_exceeds_To(To, eta, seed):
    rng = np.random.default_rng(seed)
    theta = np.cumsum(rng.standard_normal(2000)) * rng.uniform(1e-7, 1e-3)
    T = dahl.dahl_torque(theta, To, eta)
    assert np.all(np.abs(T) <= To) and np.all(np.isfinite(T))


def test_steady_loop_is_eq_5_8_with_peak_eq_5_9():
    To, eta, amp = 0.016, 1.6e6, 60e-6
    n_per = 2000
    psi = np.arange(6 * n_per + 1) * 2 * math.pi / n_per
    theta = amp * np.cos(psi + math.pi)  # starts at -amp, increasing
    T = dahl.dahl_torque(theta, To, eta)
    x = eta * To * amp
    last = slice(5 * n_per, 6 * n_per + 1)
    tm = dahl.peak_torque_normalized(x)
    assert T[last].max() / To == pytest.approx(tm, rel=1e-6)
    assert -T[last].min() / To == pytest.approx(tm, rel=1e-6)
    th_bar = eta * To * theta[last]
    up = np.r_[np.diff(theta[last]) > 0, False]
    model = np.where(
        up, dahl.loop_normalized(x, th_bar, True), dahl.loop_normalized(x, th_bar, False)
    )
    assert np.max(np.abs(T[last][:-1] / To - model[:-1])) < 1e-6


def test_small_motion_is_a_spring_of_stiffness_eta_To2():
    To, eta = 0.016, 1.6e6
    theta = np.linspace(0.0, 1e-8, 50)
    T = dahl.dahl_torque(theta, To, eta)
    assert T[-1] / theta[-1] == pytest.approx(dahl.stiffness(To, eta), rel=1e-3)
    assert dahl.stiffness(To, eta) == pytest.approx(409.6)


def test_large_motion_is_coulomb_friction():
    To, eta = 0.016, 1.6e6
    theta = np.linspace(0.0, 0.05, 500)  # eta To theta = 1280: To - T = 1 / (eta theta)
    T = dahl.dahl_torque(theta, To, eta)
    assert T[-1] == pytest.approx(To, rel=1e-3)
    assert To - T[-1] == pytest.approx(1.0 / (1.0 / To + eta * 0.05), rel=1e-6)
    back = dahl.dahl_torque(theta[::-1], To, eta, T[-1])
    assert back[-1] == pytest.approx(-To, rel=1e-3)


@pytest.mark.parametrize("x", [1e-4, 0.01, 0.1, 0.5, 1.0, 3.0, 10.0, 100.0])
def test_describing_function_is_the_first_harmonic_of_the_loop(x):
    """Eq. 5.12 (corrected) against the first harmonic of the steady loop computed by eq. 5.3,
    i.e. eqs. 5.10-5.11 by quadrature."""
    To, eta = 1.0, 1.0
    amp = x / (eta * To)
    n_per = 20000
    # one cycle of the symmetric steady loop: start at -theta_o on it, T = -Tm (eq. 5.4)
    ps = -math.pi / 2 + np.arange(n_per + 1) * 2 * math.pi / n_per
    theta = amp * np.sin(ps)
    T = dahl.dahl_torque(theta, To, eta, -dahl.peak_torque_normalized(x) * To)
    assert T[-1] == pytest.approx(T[0], rel=1e-9, abs=1e-15)  # a closed loop
    T, theta, ps = T[:-1], theta[:-1], ps[:-1]
    b1 = 2 / n_per * np.sum(T * np.sin(ps))  # in phase with the angle
    a1 = 2 / n_per * np.sum(T * np.cos(ps))  # in quadrature, leading
    numeric = (b1 + 1j * a1) / amp / (eta * To * To)
    closed = dahl.describing_function(x)
    assert abs(closed - numeric) < 1e-4 * abs(numeric)
    # and the same through first_harmonic of the sampled cycle
    fh = dahl.first_harmonic(T) / dahl.first_harmonic(theta) / (eta * To * To)
    assert abs(fh - numeric) < 1e-9 * abs(numeric)


def test_describing_function_limits_and_array_form():
    assert dahl.describing_function(1e-6) == pytest.approx(1.0, abs=1e-6)
    x = 1e6  # the in-phase part falls as 2 x^-1.5, the quadrature part as 4 / (pi x)
    assert dahl.describing_function(x) == pytest.approx(4j / (math.pi * x), rel=3e-3)
    arr = dahl.describing_function(np.array([0.1, 1.0, 10.0]))
    assert arr.shape == (3,) and np.all(np.diff(np.abs(arr)) < 0)  # gain falls with amplitude
    assert np.all(np.diff(np.angle(arr)) > 0)  # and the phase lead grows
    # continuous across the small-x series branch
    assert abs(dahl.describing_function(0.999e-3) - dahl.describing_function(1.001e-3)) < 1e-5
    with pytest.raises(ValueError):
        dahl.describing_function(0.0)


@pytest.mark.parametrize("x", [1e8, 1e12, 1e20])
def test_describing_function_deep_in_coulomb_friction_is_finite(x):
    """A coverage rig's bearing (a large motion on a small To) gave x where 1 - Tm^2 rounds to 0:
    the in-phase part was 0/0 with a divide-by-zero warning. Both parts keep their asymptotes."""
    d = dahl.describing_function(x)  # the suite makes any warning an error
    assert d.real == pytest.approx(2 * x**-1.5, rel=1e-3)
    assert d.imag == pytest.approx(4 / (math.pi * x), rel=1e-3)


def test_model_rejects_bad_arguments():
    with pytest.raises(ValueError, match="must be > 0"):
        dahl.dahl_torque(np.zeros(3), -1.0, 1.0)
    with pytest.raises(ValueError, match="initial torque"):
        dahl.dahl_torque(np.zeros(3), 1.0, 1.0, 2.0)
    with pytest.raises(ValueError, match="non-empty"):
        dahl.dahl_torque(np.zeros(0), 1.0, 1.0)
    with pytest.raises(ValueError, match="cutoff"):
        dahl.lowpass(np.zeros(100), 100.0, 60.0)


# ---------------------------------------------------------------------------- signals, cycles
def test_bearing_torque_removes_inertial_and_viscous_torques():
    fs = 400.0
    t = np.arange(4000) / fs
    w = 2 * math.pi * 0.4
    theta = 300e-6 * np.sin(w * t)
    friction = 0.01 * np.tanh(np.cos(w * t) * 5)
    I, c, kpa = 0.7, 1.03, 6.96
    pa = (friction + c * 300e-6 * w * np.cos(w * t) - I * 300e-6 * w * w * np.sin(w * t)) / kpa
    T = dahl.bearing_torque(
        pa, theta, fs, torque_per_pa_Nm_per_V=kpa, viscous_Nms=c, inertia_kg_m2=I
    )
    assert np.max(np.abs(T - friction)[5:-5]) < 1e-3 * 0.01


@pytest.mark.parametrize("k", [0.0, 450.0])
def test_driven_angle_is_the_platforms_answer_to_its_drive(k):
    """The angle a drive moves a spring-mass-damper through, against an ODE solver's: equal
    above the drive's slowest content (its mean and end-to-end line are no motion it knows)."""
    fs, I, c, kpa = 400.0, 0.3, 0.9, 6.96
    rng = np.random.default_rng(3)
    n = 8000
    # a drive with content from 2 Hz up: steps of a DAC and a random part
    pa = dahl.lowpass(rng.standard_normal(n), fs, 60.0) * 1e-3
    pa += 2e-3 * np.floor(np.sin(2 * math.pi * 0.4 * np.arange(n) / fs) * 20) / 20
    sys_ = scipy.signal.lti([kpa], [I, c, k] if k else [I, c, 1e-9])
    _, theta, _ = scipy.signal.lsim(sys_, pa - pa.mean(), np.arange(n) / fs)
    got = dahl.driven_angle(
        pa, fs, torque_per_pa_Nm_per_V=kpa, viscous_Nms=c, inertia_kg_m2=I, stiffness_Nm_per_rad=k
    )

    def high(x):
        return (x - dahl.lowpass(x, fs, 10.0))[1000:-1000]

    err = np.std(high(got) - high(theta)) / np.std(high(theta))
    assert err < 0.02


def test_command_frequency_and_segments_of_a_ladder():
    _, cmd = ladder([500e-6, 100e-6, 20e-6, 5e-6], cycles=5, lead_s=3.3)
    fs = FS
    f = dahl.command_frequency(cmd, fs)
    assert f == pytest.approx(F0, rel=1e-5)
    segs = dahl.find_segments(cmd, fs, f, settle_cycles=1)
    # the one-period windows line up with the amplitude steps wherever they fall
    assert [s.n_cycles for s in segs] == [4, 4, 4, 4]
    assert [s.n_cycles for s in dahl.find_segments(cmd, fs, f, settle_cycles=1, offsets=1)] == [
        3,
        3,
        3,
        3,
    ]
    _, aligned = ladder([500e-6, 100e-6, 20e-6, 5e-6], cycles=5)
    assert [s.n_cycles for s in dahl.find_segments(aligned, fs, F0, settle_cycles=1)] == [
        4,
        4,
        4,
        4,
    ]
    assert [s.n_cycles for s in dahl.find_segments(aligned, fs, F0, settle_cycles=2)] == [
        3,
        3,
        3,
        3,
    ]
    amps = [s.command_amplitude for s in segs]
    assert amps == sorted(amps, reverse=True)
    assert amps[0] == pytest.approx(500e-6, rel=0.02) and amps[-1] == pytest.approx(5e-6, rel=0.02)
    per = fs / F0
    for s in segs:
        assert s.start - s.lead_start == pytest.approx(per, abs=1)  # one settling cycle left out
        assert (s.stop - s.start) == pytest.approx(s.n_cycles * per, abs=1)
    # segments do not overlap and follow the ladder in time
    assert all(a.stop <= b.lead_start for a, b in zip(segs, segs[1:]))


def test_segments_need_enough_cycles_and_a_sinusoid():
    _, cmd = ladder([100e-6], cycles=2)
    assert dahl.find_segments(cmd, FS, F0, settle_cycles=1) == []
    with pytest.raises(ValueError, match="no sinusoid"):
        dahl.command_frequency(np.zeros(1000), FS)


def test_synchronous_average_and_first_harmonic():
    fs, f = 100.0, 0.3  # 333.3 samples a period: not whole
    k = np.arange(int(fs / f * 10))
    x = 2.0 * np.cos(2 * math.pi * f * k / fs + 0.7) + 0.5
    cyc = dahl.synchronous_average(x, fs, f, 0, len(k) - 50, bins=100)
    a = dahl.first_harmonic(cyc)
    assert abs(a) == pytest.approx(2.0, rel=2e-3)
    assert np.angle(a) == pytest.approx(
        0.7 + math.pi / 100, abs=5e-3
    )  # phase of the first bin's centre
    with pytest.raises(ValueError, match="phase bins"):
        dahl.synchronous_average(x, fs, f, 0, 50, bins=100)


# ---------------------------------------------------------------------------- the fit
def synthetic(
    To: float, eta: float, noise_Nm: float, seed: int = 0, amplitudes_urad=(500, 150, 40, 10, 4)
):
    theta, cmd = ladder([a * 1e-6 for a in amplitudes_urad], cycles=4)
    T = ode_dahl(theta, To, eta)
    rng = np.random.default_rng(seed)
    return theta, cmd, T + noise_Nm * rng.standard_normal(len(T))


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(To=st.floats(0.006, 0.04), eta=st.floats(6e5, 4e6), seed=st.integers(0, 1000))
def test_fit_recovers_To_and_eta_from_an_independent_integration(To, eta, seed):
    """Loops from solve_ivp of eq. 5.2 with 1 % noise and a torque offset: the fit (closed form
    along the angle, offsets per amplitude) recovers To, eta and eta To^2 to ~1 %."""
    theta, cmd, T = synthetic(To, eta, 0.01 * To, seed)
    T = T + 0.1 * To  # an amplifier offset
    segs = dahl.find_segments(cmd, FS, F0, settle_cycles=1)
    assert len(segs) == 5
    fit = dahl.fit_dahl(theta, T, segs, FS)
    assert fit.To_Nm == pytest.approx(To, rel=0.01)
    assert fit.eta_per_Nm == pytest.approx(eta, rel=0.02)
    assert fit.stiffness_Nm_per_rad == pytest.approx(eta * To * To, rel=0.02)
    assert all(off == pytest.approx(0.1 * To, abs=0.01 * To) for off in fit.offsets_Nm)
    # the statistical errors are honest for white noise: the truth within 5 standard errors
    assert abs(fit.To_Nm - To) < 5 * fit.To_se_Nm + 1e-6 * To
    assert abs(fit.eta_per_Nm - eta) < 5 * fit.eta_se_per_Nm + 1e-6 * eta
    assert fit.residual_rms_total_Nm == pytest.approx(0.01 * To, rel=0.2)
    # each amplitude's leverage on each figure: its share of what the fit knows of it
    lev = np.array(fit.leverage)
    assert lev.shape == (5, 3) and np.all(lev >= 0) and np.allclose(lev.sum(axis=0), 1.0)
    assert np.argmax(lev[:, 0]) == np.argmax(
        [s.command_amplitude for s in segs]
    )  # the largest loop fixes To


def test_fit_with_smoothing_and_the_path_scan():
    To, eta = 0.016, 1.6e6
    theta, cmd, T = synthetic(To, eta, 2e-4)
    fc = 12.5 * F0
    torque = dahl.lowpass(T, FS, fc)
    segs = dahl.find_segments(cmd, FS, F0)
    fit, scan = dahl.fit_dahl_path(
        theta,
        torque,
        segs,
        FS,
        smooth_hz=fc,
        cutoffs_hz=[6.0, 9.0, 14.0, 20.0],
        step=5,
        independent_every=20,
    )
    assert fit.To_Nm == pytest.approx(To, rel=0.01)
    assert fit.eta_per_Nm == pytest.approx(eta, rel=0.03)
    assert (
        scan.cutoff_hz == sorted(scan.cutoff_hz) and fit.path_cutoff_hz == scan.cutoff_hz[scan.best]
    )
    assert scan.residual_rms_Nm[scan.best] == min(scan.residual_rms_Nm)
    assert len(fit.model_Nm) == fit.stop - fit.start


def test_a_wrong_model_fits_badly():
    """Viscous damping is not Dahl friction (its torque grows with the amplitude): the fit's
    residual says so, so the procedure's quality limit has something to catch. A pure spring
    is Dahl's small-motion limit: it fits, with eta To theta_o << 1 at every amplitude (which
    the procedure's regime limits catch)."""
    theta, cmd = ladder([500e-6, 150e-6, 40e-6, 10e-6], cycles=4)
    segs = dahl.find_segments(cmd, FS, F0)
    T = 20.0 * np.gradient(theta) * FS
    fit = dahl.fit_dahl(theta, T, segs, FS)
    assert fit.residual_rms_total_Nm / (0.5 * np.ptp(T)) > 0.05
    spring = dahl.fit_dahl(theta, 30.0 * theta, segs, FS)
    assert spring.stiffness_Nm_per_rad == pytest.approx(30.0, rel=0.01)
    assert spring.eta_per_Nm * spring.To_Nm * 500e-6 < 0.5


def test_fit_refuses_nan_and_no_segments():
    theta, cmd, T = synthetic(0.016, 1.6e6, 0.0)
    segs = dahl.find_segments(cmd, FS, F0)
    T[segs[1].start + 3] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        dahl.fit_dahl(theta, T, segs, FS)
    with pytest.raises(ValueError, match="no cycles"):
        dahl.fit_dahl(theta, T, [], FS)


# ---------------------------------------------------------------------------- the angle's lag
def test_measure_lag_uses_the_command_as_instrument():
    """A rigid platform driven by a DAC staircase plus feedback of the sensor's own noise (as
    the servo does); the recorded angle lags by 3 ms and carries that same noise. The lag comes
    back within its error from the command's lines; the plain ratio angle/drive at the same
    lines, biased by the shared noise, does not."""
    fs, f0, ups, n_per, cycles, lag = 400.0, 0.4, 100, 1000, 12, 3e-3
    inertia, visc, kt = 0.7, 1.0, 7.0
    rng = np.random.default_rng(4)
    n = n_per * cycles
    t = np.arange(n) / fs
    stair = 1e-3 * np.sin(2 * math.pi * (np.floor(t * f0 * ups) + 0.5) / ups)
    noise = 1e-9 * rng.standard_normal(n)  # the sensor's noise (rad)
    drive = stair - 2e4 * noise  # the servo feeds the noise in
    f = np.fft.rfftfreq(n, 1 / fs)
    w = 2 * math.pi * f
    with np.errstate(divide="ignore", invalid="ignore"):
        plant = np.where(w > 0, kt / (-inertia * w * w + 1j * visc * w), 0.0)
    theta = np.fft.irfft(np.fft.rfft(drive) * plant, n)
    seen = np.fft.irfft(
        np.fft.rfft(theta + noise) * np.exp(-1j * w * lag), n
    )  # the instrument's lag
    segs = [dahl.Segment(n_per, n, 0, cycles - 1, 1e-3)]

    def rigid(x):
        return kt / (-inertia * x * x + 1j * visc * x)

    m = dahl.measure_lag(stair, seen, drive, fs, f0, segs, rigid, min_hz=10.0, max_hz=180.0)
    assert m.n_cycles == cycles - 1 and m.frequencies_hz[0] == pytest.approx(40.0, abs=0.5)
    assert abs(m.lag_s - lag) < max(3 * m.se_s, 2e-5) and m.se_s < 2e-4
    # the usual H1 estimate at the strongest line (cross over auto spectrum of the drive): the
    # shared noise pulls it far off
    k = int(round(m.frequencies_hz[0] / (fs / n_per)))
    blocks = n_per + np.arange(cycles - 1)[:, None] * n_per + np.arange(n_per)
    e = np.exp(-2j * math.pi * k * np.arange(n_per) / n_per)
    A, D = seen[blocks] @ e, drive[blocks] @ e
    naive = np.sum(A * np.conj(D)) / np.sum(np.abs(D) ** 2)
    wk = 2 * math.pi * k * fs / n_per
    naive_lag = -np.angle(naive / rigid(np.array([wk]))[0]) / wk
    print(
        f"lag {m.lag_s * 1e3:.4f} +- {m.se_s * 1e3:.4f} ms, H1 {naive_lag * 1e3:.4f} ms, true {lag * 1e3} ms"
    )
    assert abs(naive_lag - lag) > 5 * m.se_s


def test_measure_lag_refuses_a_smooth_command():
    fs, f0, n_per = 400.0, 0.4, 1000
    t = np.arange(6 * n_per) / fs
    cmd = np.sin(2 * math.pi * f0 * t)
    segs = [dahl.Segment(n_per, 6 * n_per, 0, 5, 1.0)]
    with pytest.raises(ValueError, match="no line"):
        dahl.measure_lag(
            cmd, cmd, cmd, fs, f0, segs, lambda x: 1.0 / (-x * x), min_hz=10.0, max_hz=180.0
        )


def test_path_envelope_spans_the_bandwidths_the_residual_cannot_tell_apart():
    """The scan's estimates over the stretch whose residual is within the tolerance of the
    least, interpolated in ln cutoff at the ends; nothing beyond it."""
    cut = [10.0, 12.5, 15.625, 19.53]
    scan = dahl.PathScan(
        cut,
        [2.0, 1.05, 1.0, 1.5],
        [1.0, 1.0, 1.0, 1.0],
        [math.e**-0.2, math.e**-0.1, 1.0, math.e**0.1],
        best=2,
    )
    down, up = scan.envelope(0.10)
    # left: 12.5 is within 10 % (ln eta -0.1); on to 10.0 the limit 1.1 is reached a twentieth of the way
    assert down[1] == pytest.approx(0.1 + (1.1 - 1.05) / (2.0 - 1.05) * 0.1)
    # right: the limit is reached a fifth of the way to 19.53 (ln eta +0.1)
    assert up[1] == pytest.approx(0.2 * 0.1)
    assert down[0] == up[0] == 0.0  # To the same everywhere
    assert all(np.allclose(side, 0.0) for side in scan.envelope(0.0))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    n=st.integers(min_value=28, max_value=3000),
    order=st.sampled_from([1, 2, 3, 4, 6]),
    cutoff=st.floats(min_value=0.01, max_value=0.49),
    seed=st.integers(min_value=0, max_value=2**32 - 1),
    scale=st.sampled_from([1e-7, 1.0, 1e4]),
)
def test_lowpass_is_scipys_sosfiltfilt_bit_for_bit(n, order, cutoff, seed, scale):
    """The compiled zero-phase filter is scipy's ``sosfiltfilt`` (odd extension, steady-state
    starts) to the last bit, on walks, noise and steps, whatever the order and cutoff."""
    fs = 400.0
    rng = np.random.default_rng(seed)
    x = scale * np.cumsum(rng.standard_normal(n)) + scale * (rng.random(n) > 0.7)
    sos = scipy.signal.butter(order, cutoff * fs, fs=fs, output="sos")
    edge = 3 * (2 * len(sos) + 1 - min(np.sum(sos[:, 2] == 0), np.sum(sos[:, 5] == 0)))
    if n <= edge:
        with pytest.raises(ValueError, match="too few"):
            dahl.lowpass(x, fs, cutoff * fs, order)
        return
    assert np.array_equal(dahl.lowpass(x, fs, cutoff * fs, order), scipy.signal.sosfiltfilt(sos, x))
    two = np.vstack([x[::-1], x])  # more than one dimension: scipy's, along the last axis
    assert np.array_equal(
        dahl.lowpass(two, fs, cutoff * fs, order)[1], dahl.lowpass(x, fs, cutoff * fs, order)
    )
