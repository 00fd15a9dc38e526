"""Dahl's solid-friction model of the gimbal bearings and its identification (thesis Ch. V F).

The model (eq. 5.1-5.2): the bearing's friction torque T changes only with the angle,

    dT/dtheta = eta (T - To)^2    (thetadot > 0)                              # eq. 5.2a
    dT/dtheta = eta (T + To)^2    (thetadot < 0)                              # eq. 5.2b

To the running (Coulomb) torque, eta a constant; for small motion it is a spring of stiffness
eta To^2, for large motion Coulomb friction of level To (after eq. 5.3). Over any monotone
piece of the angle it integrates in closed form (eq. 5.3):

    1 / (To - T) = eta theta + c1    (thetadot > 0)                           # eq. 5.3a
    1 / (To + T) = -eta theta + c2   (thetadot < 0)                           # eq. 5.3b

so ``dahl_torque`` is exact along any sampled angle (the angle taken as piecewise monotone
between samples), whatever the step.

Identification (the ``hysteresis`` procedure, ``fbs analyze hysteresis``):

* the bearing torque is what the motor applies less what accelerates and damps the platform,
  ``T = (Kp Km / Ra) V_pa - (D + Km Kb / Ra) thetadot - I thetaddot`` (eq. 3.23-3.27), every
  constant from the rig's data sheet (``bearing_torque``);
* the sinusoidal command is cut into cycles of constant amplitude (``find_segments``);
* To and eta are fitted by integrating eq. 5.2 along the whole measured angle (so the
  bearing's memory across amplitude changes is modelled too) and matching the measured torque
  in least squares, with one torque offset per amplitude (``fit_dahl``);
* loops are averaged synchronously over the cycles of each amplitude (``synchronous_average``)
  for the torque-angle plots (Figs. 51, 53, 54) and the describing function (eq. 5.12,
  Fig. 57, ``describing_function``).

SI inside (rad, N m, s); units are in the names at the edges.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numba
import numpy as np
import scipy.fft
import scipy.optimize
import scipy.signal


# ---------------------------------------------------------------------------- the model
@numba.njit(cache=True, nogil=True)
def _dahl_path(theta: np.ndarray, To: float, eta: float, T0: float) -> np.ndarray:
    out = np.empty(theta.shape[0])
    T = T0
    out[0] = T
    for k in range(1, theta.shape[0]):
        d = theta[k] - theta[k - 1]
        if d > 0.0:  # eq. 5.3a: 1/(To - T) grows by eta d
            T = To if T >= To else To - 1.0 / (1.0 / (To - T) + eta * d)
        elif d < 0.0:  # eq. 5.3b: 1/(To + T) grows by eta |d|
            T = -To if T <= -To else 1.0 / (1.0 / (T + To) - eta * d) - To
        out[k] = T
    return out


def dahl_torque(
    theta_rad: np.ndarray, To_Nm: float, eta_per_Nm: float, T0_Nm: float = 0.0
) -> np.ndarray:
    """Dahl friction torque (N m) along a sampled angle path (rad), starting at ``T0_Nm``:
    eq. 5.2 integrated exactly (eq. 5.3) over each monotone step between samples."""
    theta = np.ascontiguousarray(theta_rad, dtype=float)
    if theta.ndim != 1 or len(theta) == 0:
        raise ValueError("dahl_torque: theta must be a non-empty 1-D array")
    if not (To_Nm > 0 and eta_per_Nm > 0):
        raise ValueError(
            f"dahl_torque: To = {To_Nm!r} N m and eta = {eta_per_Nm!r} /N m must be > 0"
        )
    if not abs(T0_Nm) <= To_Nm:
        raise ValueError(
            f"dahl_torque: initial torque {T0_Nm!r} N m is outside +-To = {To_Nm!r} N m"
        )
    return _dahl_path(theta, float(To_Nm), float(eta_per_Nm), float(T0_Nm))


def stiffness(To_Nm: float, eta_per_Nm: float) -> float:
    """Small-motion stiffness eta To^2 (N m/rad), after eq. 5.3."""
    return eta_per_Nm * To_Nm * To_Nm


def peak_torque_normalized(theta_o_bar: np.ndarray | float) -> np.ndarray | float:
    """Tm/To of the symmetric loop of normalized amplitude theta_o_bar = eta To theta_o (eq. 5.9)."""
    x = np.asarray(theta_o_bar, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        # (sqrt(1 + 4 x^2) - 1) / (2 x), written without the cancellation at small x
        tm = np.where(x > 0, 2.0 * x / (np.sqrt(1.0 + 4.0 * x * x) + 1.0), 0.0)
    return tm if tm.ndim else float(tm)


def loop_normalized(theta_o_bar: float, theta_bar: np.ndarray, increasing: bool) -> np.ndarray:
    """The symmetric steady loop T/To against theta_bar = eta To theta in -theta_o_bar..theta_o_bar,
    on its increasing (eq. 5.8a) or decreasing (eq. 5.8b) branch."""
    tm = peak_torque_normalized(theta_o_bar)
    s = 1.0 - tm * tm
    th = np.asarray(theta_bar, dtype=float)
    if increasing:
        return (tm * tm + s * th) / (1.0 + s * th)  # eq. 5.8a
    return -(tm * tm - s * th) / (1.0 - s * th)  # eq. 5.8b


def describing_function(theta_o_bar: np.ndarray | float) -> np.ndarray | complex:
    """Normalized sinusoidal-input describing function (T_D/theta_o) e^{j phi} / (eta To^2) of
    Dahl's model at normalized amplitude theta_o_bar = eta To theta_o (eq. 5.12, Fig. 57).

    The real part is the in-phase (spring) part, the imaginary part the part in quadrature,
    leading the angle (dissipation). 1 for theta_o_bar << 1 (a spring of stiffness eta To^2),
    j 4 / (pi theta_o_bar) for theta_o_bar >> 1 (Coulomb friction). As printed, eq. 5.12 reads
    ``sqrt(1 - [(1 - Tm)^2 theta_o])`` in the real part; the integral (5.10) gives
    sqrt(1 - [(1 - Tm^2) theta_o]^2) = sqrt(1 - Tm^2) (since (1 - Tm^2) theta_o = Tm by
    eq. 5.9), which is what is evaluated here (and checked against quadrature in the tests).
    """
    x = np.asarray(theta_o_bar, dtype=float)
    if np.any(~(x > 0)):
        raise ValueError("describing_function: theta_o_bar must be > 0")
    tm = np.asarray(peak_torque_normalized(x))
    # 1 - Tm^2 = Tm / x (eq. 5.9) exactly: 1 - Tm^2 itself is 0 in floating point once Tm
    # rounds to 1 (x above ~1e8, deep in Coulomb friction), and Re divided by it
    c = np.sqrt(tm / x)
    # 1/sqrt(1 - Tm^2) - 1 and ln((1 + Tm)/(1 - Tm)) - 2 Tm, both without cancellation at small x
    inv_m1 = tm * tm / (c * (1.0 + c))
    small = x < 1e-3
    # series for small x: Re -> 1 - 3x^2/2.., Im -> (8/(3 pi)) x - ..; exact formula elsewhere
    with np.errstate(divide="ignore", invalid="ignore"):
        re = np.where(small, 1.0 - 1.5 * x * x, 2.0 / (x * x) * inv_m1)
        # 1 - Tm = (1 - Tm^2) / (1 + Tm) = Tm / (x (1 + Tm)), finite where 1 - Tm rounds to 0
        log_term = np.log1p(tm) - np.log(tm / (x * (1.0 + tm)))
        im = np.where(
            small, 8.0 / (3.0 * math.pi) * x, (4.0 / math.pi - 2.0 / (math.pi * x) * log_term) / x
        )
    out = re + 1j * im
    return out if out.ndim else complex(out)


# ---------------------------------------------------------------------------- signals
def lowpass(x: np.ndarray, fs_hz: float, cutoff_hz: float, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass (forward and backward): no lag between channels."""
    if not 0 < cutoff_hz < 0.5 * fs_hz:
        raise ValueError(
            f"low-pass cutoff {cutoff_hz:g} Hz must be between 0 and half the sample rate "
            f"({0.5 * fs_hz:g} Hz)"
        )
    sos, zi, edge = _butter_sos(order, cutoff_hz, fs_hz)
    x = np.asarray(x, dtype=float)
    if x.ndim != 1:
        return scipy.signal.sosfiltfilt(sos.copy(), x, axis=-1)  # (scipy wants sos writable)
    if x.shape[0] <= edge:
        raise ValueError(
            f"low-pass: {x.shape[0]} samples are too few for its {edge}-sample edge extension"
        )
    return _filtfilt(sos, zi, np.ascontiguousarray(x), edge)


@functools.lru_cache(maxsize=64)
def _butter_sos(order: int, cutoff_hz: float, fs_hz: float) -> tuple[np.ndarray, np.ndarray, int]:
    """The Butterworth sections, their steady-state initial conditions (``sosfilt_zi``) and
    the edge extension's length, once per (order, cutoff, rate): a fit filters each of its
    model's thousands of evaluations at one cutoff, and the design cost more than the
    filtering (1.9 of 6.6 s of a hysteresis analysis). Shared: read only."""
    sos = scipy.signal.butter(order, cutoff_hz, fs=fs_hz, output="sos")
    ntaps = 2 * len(sos) + 1 - min(int(np.sum(sos[:, 2] == 0)), int(np.sum(sos[:, 5] == 0)))
    return sos, scipy.signal.sosfilt_zi(sos), 3 * ntaps  # sosfiltfilt's default padlen


@numba.njit(cache=True, nogil=True)
def _sosfilt_inplace(sos: np.ndarray, z: np.ndarray, y: np.ndarray) -> None:
    """Second-order sections in direct form II transposed over ``y``, in place, from state
    ``z``: scipy's ``_sosfilt`` loop, operation for operation (so the same bits)."""
    for n in range(y.shape[0]):
        x_cur = y[n]
        for s in range(sos.shape[0]):
            x_new = sos[s, 0] * x_cur + z[s, 0]
            z[s, 0] = sos[s, 1] * x_cur - sos[s, 4] * x_new + z[s, 1]
            z[s, 1] = sos[s, 2] * x_cur - sos[s, 5] * x_new
            x_cur = x_new
        y[n] = x_cur


@numba.njit(cache=True, nogil=True)
def _filtfilt(sos: np.ndarray, zi: np.ndarray, x: np.ndarray, edge: int) -> np.ndarray:
    """``scipy.signal.sosfiltfilt(sos, x)`` (odd extension of ``edge`` samples each end, each
    pass started in the steady state of its first sample) bit for bit, without its per-call
    validation and ``sosfilt_zi`` solve: a Dahl fit filters its model 10^3-10^4 times, and
    those took a third of the filtering (tests/procedures/analysis/test_dahl.py compares)."""
    n = x.shape[0]
    y = np.empty(n + 2 * edge)
    for i in range(edge):
        y[i] = 2.0 * x[0] - x[edge - i]
        y[edge + n + i] = 2.0 * x[n - 1] - x[n - 2 - i]
    y[edge : edge + n] = x
    _sosfilt_inplace(sos, zi * y[0], y)
    back = y[::-1].copy()
    _sosfilt_inplace(sos, zi * back[0], back)
    return back[edge + n - 1 : edge - 1 : -1].copy()


def shift(x: np.ndarray, fs_hz: float, advance_s: float) -> np.ndarray:
    """``x(t + advance_s)`` of a smooth signal by linear interpolation (ends held)."""
    if advance_s == 0.0:
        return np.asarray(x, dtype=float)
    n = np.arange(len(x), dtype=float)
    return np.interp(n + advance_s * fs_hz, n, x)


def bearing_torque(
    pa_V: np.ndarray,
    theta_rad: np.ndarray,
    fs_hz: float,
    *,
    torque_per_pa_Nm_per_V: float,
    viscous_Nms: float,
    inertia_kg_m2: float,
) -> np.ndarray:
    """The bearing's friction torque (N m) from the power-amplifier input and the angle:

        T = (Kp Km / Ra) V_pa - (D + Km Kb / Ra) thetadot - I thetaddot       (eq. 3.23-3.27)

    i.e. the motor torque less the platform's viscous and inertial torques. Both inputs should
    be low-passed the same way beforehand (the derivatives amplify noise)."""
    omega = np.gradient(theta_rad) * fs_hz
    alpha = np.gradient(omega) * fs_hz
    return torque_per_pa_Nm_per_V * np.asarray(pa_V) - viscous_Nms * omega - inertia_kg_m2 * alpha


def driven_angle(
    pa_V: np.ndarray,
    fs_hz: float,
    *,
    torque_per_pa_Nm_per_V: float,
    viscous_Nms: float,
    inertia_kg_m2: float,
    stiffness_Nm_per_rad: float,
) -> np.ndarray:
    """The angle (rad) the power-amplifier input drives the platform through, the bearing taken
    as a spring of stiffness k (``bearing_torque`` solved for the angle, eq. 3.23-3.27):

        theta(w) = (Kp Km / Ra) V_pa(w) / (k + j w (D + Km Kb / Ra) - I w^2)

    A second view of the platform's motion, free of the autocollimator's noise: far above
    sqrt(k / I) the inertia alone sets it and it is the platform's own motion (the drive is
    the torque the platform really feels, noise and all); near and below it the bearing's
    stiffness, which Dahl's model makes vary along the loop from 0 to 4 k, makes it only an
    approximation. No mean (0 at DC); the drive's spectrum is ``Advance``'s, the straight line
    through the record's ends taken out first, so its ends do not ring."""
    spec = Advance(pa_V, fs_hz)
    w = spec.w
    den = stiffness_Nm_per_rad + 1j * w * viscous_Nms - inertia_kg_m2 * w * w
    h = np.zeros(len(w), dtype=complex)
    h[1:] = torque_per_pa_Nm_per_V / den[1:]
    return scipy.fft.irfft(spec.spec * h, spec.nfft)[: spec.n]


# ---------------------------------------------------------------------------- cycles
@dataclass(frozen=True)
class Segment:
    """Cycles of one command amplitude: samples ``start .. stop`` (the kept, settled cycles),
    ``lead_start`` where the amplitude began (settling cycles included)."""

    start: int
    stop: int
    lead_start: int
    n_cycles: int
    command_amplitude: float  # in the command's units (V)


def command_frequency(cmd: np.ndarray, fs_hz: float) -> float:
    """The frequency (Hz) of the sinusoidal command: the periodogram's peak, refined on a fine
    grid around it."""
    x = np.asarray(cmd, dtype=float)
    x = x - np.mean(x)
    n = len(x)
    if n < 8 or not np.any(x):
        raise ValueError("the command channel carries no sinusoid (it is constant or too short)")
    nfft = 1 << int(math.ceil(math.log2(4 * n)))
    spec = np.abs(np.fft.rfft(x, nfft))
    f = np.fft.rfftfreq(nfft, 1.0 / fs_hz)
    lo = 2.0 / (n / fs_hz)  # at least two cycles in the record
    spec[f < lo] = 0.0
    k = int(np.argmax(spec))
    if spec[k] == 0.0:
        raise ValueError("the command channel carries no sinusoid of at least two cycles")
    df = fs_hz / nfft
    grid = np.linspace(max(lo, f[k] - 2 * df), f[k] + 2 * df, 81)
    # decimate for the fine search: a mean over blocks keeps the low frequencies
    step = max(1, int(fs_hz / (40.0 * f[k])))
    m = n // step
    xd = x[: m * step].reshape(m, step).mean(axis=1)
    td = (np.arange(m) * step + (step - 1) / 2) / fs_hz
    power = np.array([abs(np.dot(xd, np.exp(-2j * math.pi * g * td))) for g in grid])
    f0 = float(grid[int(np.argmax(power))])
    # the periodogram's peak is pulled by the amplitude steps (leakage from -f): refine from the
    # phase advance of the fundamental from one cycle to the next
    for _ in range(2):
        _, amps, _ = cycle_fits(x, fs_hz, f0)
        if len(amps) < 2:
            break
        m = np.abs(amps)
        # pairs of whole cycles at one amplitude (a cycle with a step in it has a biased phase)
        same = np.abs(m[1:] - m[:-1]) < 0.05 * np.maximum(m[1:], m[:-1])
        w = np.where(same, m[1:] * m[:-1], 0.0)
        if not np.any(w > 0):
            break
        dphi = np.angle(amps[1:] * np.conj(amps[:-1]))
        f0 += float(np.sum(w * dphi) / np.sum(w)) / (2 * math.pi) * f0
    return f0


def cycle_fits(
    x: np.ndarray, fs_hz: float, freq_hz: float, start: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Window boundaries (one period each, from ``start``) and per window the complex
    first-harmonic amplitude (x ~ Re(A e^{j w t}), t from sample 0) and residual rms."""
    per = fs_hz / freq_hz
    n_win = int((len(x) - start) // per)
    bounds = start + np.rint(np.arange(n_win + 1) * per).astype(np.int64)
    fits = np.empty((n_win, 3))
    resid = np.empty(n_win)
    _window_sines(
        np.ascontiguousarray(x, dtype=float), bounds, 2 * math.pi * freq_hz / fs_hz, fits, resid
    )
    return bounds, fits[:, 0] + 1j * fits[:, 1], resid


@numba.njit(cache=True, nogil=True)
def _window_sines(x, bounds, w, fits, resid):
    """Least squares of ``x`` on cos(w k), -sin(w k), 1 in each window bounds[i]..bounds[i+1]
    (k the sample index): the coefficients into ``fits[i]``, the residual rms into ``resid[i]``.
    The normal equations, solved per window (the three columns are near orthogonal over a
    whole period): ``find_segments`` tries 16 window grids of a record's every cycle, and a
    least-squares call per window was a sixth of a hysteresis analysis."""
    for i in range(len(bounds) - 1):
        a, b = bounds[i], bounds[i + 1]
        g = np.zeros((3, 3))
        r = np.zeros(3)
        for k in range(a, b):
            row = (math.cos(w * k), -math.sin(w * k), 1.0)
            for p in range(3):
                r[p] += row[p] * x[k]
                for q in range(3):
                    g[p, q] += row[p] * row[q]
        coef = np.linalg.solve(g, r)
        ss = 0.0
        for k in range(a, b):
            e = x[k] - (coef[0] * math.cos(w * k) - coef[1] * math.sin(w * k) + coef[2])
            ss += e * e
        fits[i, 0], fits[i, 1], fits[i, 2] = coef[0], coef[1], coef[2]
        resid[i] = math.sqrt(ss / (b - a))


def find_segments(
    cmd: np.ndarray,
    fs_hz: float,
    freq_hz: float,
    *,
    settle_cycles: int = 1,
    min_cycles: int = 2,
    tolerance: float = 0.1,
    offsets: int = 16,
) -> list[Segment]:
    """Runs of consecutive command cycles with the same amplitude (within ``tolerance``); the
    first ``settle_cycles`` of each run are left out of the kept cycles. The one-period windows
    are laid from each of ``offsets`` starting points within the first period; the grid that
    keeps most cycles, and of those the one whose kept cycles are the cleanest sinusoids (no
    amplitude step inside), wins."""
    cmd = np.asarray(cmd, dtype=float)
    per = fs_hz / freq_hz
    best: list[Segment] = []
    best_key = (0, 0.0)
    for k in range(max(1, offsets)):
        segs, misfit = _segments_from(
            cmd,
            fs_hz,
            freq_hz,
            int(round(k * per / max(1, offsets))),
            settle_cycles,
            min_cycles,
            tolerance,
        )
        key = (sum(s.n_cycles for s in segs), -misfit)
        if key > best_key:
            best, best_key = segs, key
    return best


def _segments_from(
    cmd: np.ndarray,
    fs_hz: float,
    freq_hz: float,
    start: int,
    settle_cycles: int,
    min_cycles: int,
    tolerance: float,
) -> tuple[list[Segment], float]:
    """The segments on one window grid, and the worst relative sine-fit residual of their kept cycles."""
    bounds, amps, resid = cycle_fits(cmd, fs_hz, freq_hz, start)
    if len(amps) == 0:
        return [], 0.0
    mag = np.abs(amps)
    active = (mag > 1e-3 * mag.max()) & (resid < 0.3 * mag)
    segs: list[Segment] = []
    misfit = 0.0
    i = 0
    while i < len(mag):
        if not active[i]:
            i += 1
            continue
        j = i + 1
        while j < len(mag) and active[j] and abs(mag[j] / mag[i] - 1.0) < tolerance:
            j += 1
        kept = j - i - settle_cycles
        if kept >= min_cycles:
            segs.append(
                Segment(
                    int(bounds[i + settle_cycles]),
                    int(bounds[j]),
                    int(bounds[i]),
                    kept,
                    float(np.median(mag[i:j])),
                )
            )
            misfit = max(
                misfit, float(np.max(resid[i + settle_cycles : j] / mag[i + settle_cycles : j]))
            )
        i = j
    return segs, misfit


def synchronous_average(
    x: np.ndarray, fs_hz: float, freq_hz: float, start: int, stop: int, bins: int = 200
) -> np.ndarray:
    """The mean cycle of ``x[start:stop]`` in ``bins`` phase bins (phase from ``start``), so a
    period need not be a whole number of samples."""
    k = np.arange(start, stop)
    phase = ((k - start) * freq_hz / fs_hz) % 1.0
    idx = np.minimum((phase * bins).astype(int), bins - 1)
    counts = np.bincount(idx, minlength=bins)
    if np.any(counts == 0):
        raise ValueError(
            f"synchronous average: {stop - start} samples do not fill {bins} phase bins"
        )
    return np.bincount(idx, weights=np.asarray(x, dtype=float)[start:stop], minlength=bins) / counts


def first_harmonic(cycle: np.ndarray) -> complex:
    """Complex amplitude A of the fundamental of one uniformly sampled period: x ~ Re(A e^{j psi})."""
    n = len(cycle)
    return complex(2.0 / n * np.sum(np.asarray(cycle) * np.exp(-2j * math.pi * np.arange(n) / n)))


# ---------------------------------------------------------------------------- the fit
@dataclass
class DahlFit:
    """Least-squares Dahl parameters and how well they explain the measured torque."""

    To_Nm: float
    eta_per_Nm: float
    To_se_Nm: float
    eta_se_per_Nm: float
    stiffness_Nm_per_rad: float
    stiffness_se_Nm_per_rad: float
    correlation: float  # of the To and eta estimates
    offsets_Nm: list[float]  # the torque offset of each segment
    residual_rms_Nm: list[float]  # of each segment's kept cycles
    residual_rms_total_Nm: float
    model_Nm: np.ndarray = field(repr=False)  # fitted torque, offsets included, samples start..stop
    start: int = 0
    stop: int = 0
    path_cutoff_hz: float | None = None
    n_independent: int = 0  # residual samples counted as independent for the errors
    evaluations: int = 0
    #: covariance of (ln To, ln eta): cluster-robust over the analysed cycles (``fit_dahl``)
    cov_ln: np.ndarray = field(repr=False, default_factory=lambda: np.full((2, 2), np.nan))
    #: degrees of freedom of that covariance (Student t): cycles less the fitted parameters
    dof: int = 0
    n_clusters: int = 0
    #: each segment's leverage on ln To, ln eta and ln(eta To^2): its share of what the fit
    #: knows of each, c^T J_s^T J_s c / c^T J^T J c with c = (J^T J)^-1 g (g the figure's
    #: gradient; the offsets projected out). Each figure's shares add up to 1.
    leverage: list[tuple[float, float, float]] = field(default_factory=list)
    #: the angle's further advance fitted with To and eta (``fit_dahl``'s ``lag_term_Nm``), its
    #: standard error (cluster-robust), and whether it was fitted at all
    lag_s: float = 0.0
    lag_se_s: float = math.nan
    lag_fitted: bool = False
    #: the parameters that ended on the edge of the search: no estimate (``fit_dahl``)
    at_edge: list[str] = field(default_factory=list)


def _initial_guess(
    th: np.ndarray, meas: list[np.ndarray], idx: list[np.ndarray]
) -> tuple[float, float]:
    """To from the largest loop's torque half-range, eta To^2 from the smallest loop's slope."""
    spans = [float(np.ptp(th[i])) for i in idx]
    big, small = int(np.argmax(spans)), int(np.argmin(spans))
    To0 = 0.5 * float(np.ptp(meas[big]))
    if not To0 > 0:
        raise ValueError(
            "the measured torque does not change over the cycles (a flat power-amplifier input?)"
        )
    slope = float(np.polyfit(th[idx[small]], meas[small], 1)[0]) if spans[small] > 0 else 0.0
    # no usable slope (noise): a spring that reaches To over a tenth of the smallest amplitude
    k0 = slope if slope > 0 else To0 / max(0.05 * spans[small], 1e-12)
    return To0, k0 / To0**2


def fit_dahl(
    path_rad: np.ndarray,
    torque_Nm: np.ndarray,
    segments: list[Segment],
    fs_hz: float,
    *,
    smooth_hz: float | None = None,
    step: int = 1,
    independent_every: int = 1,
    start: tuple[float, ...] | None = None,
    drop_cycle: int | None = None,
    lag_term_Nm: np.ndarray | None = None,
    max_lag_s: float = 0.0,
) -> DahlFit:
    """Least-squares To and eta of eq. 5.2 integrated along ``path_rad`` (the angle the bearing
    is taken to follow) against ``torque_Nm`` (the measured bearing torque, ``bearing_torque``).

    The integration starts at the first segment's settling cycles (from T = 0; the bearing
    forgets its initial state within a half-cycle of amplitude >> 1 / (eta To)) and runs
    through every segment, so the memory the bearing carries from one amplitude to the next is
    modelled. The residual is taken on each segment's kept cycles, every ``step``-th sample,
    less one free torque offset per segment (solved exactly for each trial To, eta: the
    power amplifier's offset, slow disturbances). With ``smooth_hz`` the model torque gets the
    zero-phase low-pass the measured torque had.

    With ``lag_term_Nm`` (the part of ``torque_Nm`` formed from the angle, -D thetadot -
    I thetaddot of ``bearing_torque``) the angle's lag behind the drive is fitted too, as a
    third parameter ``lag_s`` within +-``max_lag_s``: the angle (the path and that part of the
    torque) advanced by ``lag_s`` more (``advance``). It is told from eta by the ladder: a lag
    turns every loop by the same phase w lag, Dahl's hysteresis by a phase that grows with the
    loop's amplitude (eq. 5.12; 8 eta To theta_o / (3 pi) in the spring regime).

    Standard errors are cluster-robust over the analysed cycles (the covariance of (ln To,
    ln eta) from the spread of the cycles' scores, ``cov_ln``, with ``dof`` degrees of freedom
    for Student's t; the fitted lag's error is in it); they are statistical only. The stiffness
    eta To^2 gets the delta method. ``independent_every`` only sets ``n_independent`` (a residual
    sample per that many is counted as independent), kept for the report. ``drop_cycle``: leave
    the kept cycle of that index out of every segment's residual (the model still runs along the
    whole path). ``start``: (To, eta) or (To, eta, lag) to start from."""
    if not segments:
        raise ValueError("no cycles of constant amplitude to fit")
    theta = np.asarray(path_rad, dtype=float)
    torque = np.asarray(torque_Nm, dtype=float)
    a0 = min(s.lead_start for s in segments)
    b0 = max(s.stop for s in segments)
    th = np.ascontiguousarray(theta[a0:b0])
    if not (np.all(np.isfinite(th)) and np.all(np.isfinite(torque[a0:b0]))):
        raise ValueError(
            "the angle or the torque has non-finite samples (lost data) in the cycles to fit"
        )
    step = max(1, int(step))
    idx = [np.arange(s.start - a0, s.stop - a0, step) for s in segments]
    if (
        drop_cycle is not None
    ):  # a jackknife replicate: the drop_cycle-th kept cycle of every segment out
        idx = [i[_cycle_labels(s, i + a0, 0) != drop_cycle] for s, i in zip(segments, idx)]
    meas = [torque[a0 + i] for i in idx]
    To0, eta0 = start[:2] if start is not None else _initial_guess(th, meas, idx)
    fit_lag = lag_term_Nm is not None and max_lag_s > 0
    evals = 0
    if fit_lag:
        assert lag_term_Nm is not None
        # the advance is exact for band-limited records (a phase ramp on the spectrum); the
        # window is taken with a margin either side, so its wrap-around stays out of the cycles
        margin = int(math.ceil(max_lag_s * fs_hz)) + 64
        lo_w, hi_w = max(0, a0 - margin), min(len(theta), b0 + margin)
        path_adv = Advance(theta[lo_w:hi_w], fs_hz)
        term = np.asarray(lag_term_Nm, dtype=float)
        term_adv = Advance(term[lo_w:hi_w], fs_hz)
        sel = np.concatenate(idx) + (a0 - lo_w)
        base = np.concatenate(meas) - term[lo_w:hi_w][sel]
        bounds_i = np.cumsum([0] + [len(i) for i in idx])
    lag0 = float(start[2]) if start is not None and len(start) > 2 and fit_lag else 0.0

    def data(p: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        """The path (a0..b0) and the measured torque on each segment's residual samples."""
        if not fit_lag:
            return th, meas
        lag = p[2] * LAG_UNIT_S
        path = path_adv(lag)[a0 - lo_w : b0 - lo_w]
        tq = base + term_adv(lag)[sel]
        return np.ascontiguousarray(path), [tq[x:y] for x, y in zip(bounds_i[:-1], bounds_i[1:])]

    def model(p: np.ndarray, path: np.ndarray) -> np.ndarray:
        T = _dahl_path(path, math.exp(p[0]), math.exp(p[1]), 0.0)
        return lowpass(T, fs_hz, smooth_hz) if smooth_hz is not None else T

    def residuals(p: np.ndarray) -> np.ndarray:
        nonlocal evals
        evals += 1
        path, m_seg = data(p)
        T = model(p, path)
        out = []
        for i, m in zip(idx, m_seg):
            r = T[i] - m
            out.append(r - r.mean())  # the segment's offset, solved exactly
        return np.concatenate(out)

    span = math.log(1e3)
    p0 = np.array([math.log(To0), math.log(eta0)] + ([lag0 / LAG_UNIT_S] if fit_lag else []))
    lo_b = np.concatenate([p0[:2] - span, [-max_lag_s / LAG_UNIT_S] if fit_lag else []])
    hi_b = np.concatenate([p0[:2] + span, [max_lag_s / LAG_UNIT_S] if fit_lag else []])
    p0 = np.clip(p0, lo_b, hi_b)
    sol = scipy.optimize.least_squares(
        residuals,
        p0,
        method="trf",
        bounds=(lo_b, hi_b),
        diff_step=1e-4,
        x_scale=np.full(len(p0), 0.1),
        max_nfev=200,
    )
    if not np.all(np.isfinite(sol.x)) or not np.all(np.isfinite(sol.fun)):
        raise ValueError("the Dahl fit did not converge (non-finite parameters or residuals)")
    To, eta = math.exp(sol.x[0]), math.exp(sol.x[1])
    # a parameter on the edge of the search (ln 1e3 either side of the start) is no estimate:
    # the torque does not follow eq. 5.2 there (no friction at all, or a spring that never slips)
    edge = [
        name
        for name, x, lo_x, hi_x in zip(("To", "eta", "lag"), sol.x, lo_b, hi_b)
        if min(x - lo_x, hi_x - x) < 1e-3 * max(1.0, hi_x - lo_x)
    ]
    r = sol.fun
    n_ind = max(3, int(len(r) * step / max(1, independent_every)))
    # Cluster-robust ("sandwich") covariance with one cluster per analysed cycle: the residual
    # is correlated within a cycle (the low-pass, the platform's jitter, the bearing's memory of
    # it) but its score J_c^T r_c is nearly independent from cycle to cycle, so the spread of the
    # cycles' scores measures the estimate's error whatever the correlation inside a cycle.
    labels = np.concatenate(
        [
            _cycle_labels(s, i + a0, base_c)
            for s, i, base_c in zip(
                segments, idx, np.cumsum([0] + [s.n_cycles for s in segments[:-1]])
            )
        ]
    )
    n_cl = int(labels.max()) + 1
    n_par = len(p0)
    dof = max(1, n_cl - len(segments) - n_par)  # each segment's offset and the parameters
    J = sol.jac
    # the figures' gradients in the parameters: ln To, ln eta, ln k = 2 ln To + ln eta (the lag none)
    grad = np.zeros((n_par, 3))
    grad[:2] = [[1.0, 0.0, 2.0], [0.0, 1.0, 1.0]]
    try:
        bread = np.linalg.inv(J.T @ J)
        scores = np.zeros((n_cl, n_par))
        np.add.at(scores, labels, J * r[:, None])
        cov_full = bread @ (scores.T @ scores) @ bread * (n_cl / dof)
    except np.linalg.LinAlgError:
        bread = cov_full = np.full((n_par, n_par), np.nan)
    cov = cov_full[:2, :2]
    proj = J @ bread @ grad  # J c for ln To, ln eta, ln k
    bounds = np.cumsum([0] + [len(i) for i in idx])
    info = np.array([np.sum(proj[a:b] ** 2, axis=0) for a, b in zip(bounds[:-1], bounds[1:])])
    with np.errstate(divide="ignore", invalid="ignore"):
        shares = info / info.sum(axis=0)
    leverage = [(float(x), float(y), float(z)) for x, y, z in shares]
    var = np.diag(cov)
    se_ln = np.sqrt(np.where(var >= 0, var, np.nan))
    g = np.array([2.0, 1.0])  # ln k = 2 ln To + ln eta
    k = stiffness(To, eta)
    se_lnk = float(np.sqrt(max(float(g @ cov @ g), 0.0))) if np.all(np.isfinite(cov)) else math.nan
    corr = (
        float(cov[0, 1] / math.sqrt(var[0] * var[1]))
        if np.all(np.isfinite(cov)) and var[0] > 0 and var[1] > 0
        else math.nan
    )
    path, m_seg = data(sol.x)
    T = model(sol.x, path)
    offsets, rms = [], []
    for i, m in zip(idx, m_seg):
        d = m - T[i]
        offsets.append(float(d.mean()))
        rms.append(float(np.sqrt(np.mean((d - d.mean()) ** 2))))
    full = T.copy()
    for s, off in zip(segments, offsets):
        full[s.lead_start - a0 : s.stop - a0] += off
    lag_s = float(sol.x[2] * LAG_UNIT_S) if fit_lag else 0.0
    lag_se = (
        float(math.sqrt(cov_full[2, 2]) * LAG_UNIT_S)
        if fit_lag and cov_full[2, 2] >= 0
        else math.nan
    )
    return DahlFit(
        To,
        eta,
        To * float(se_ln[0]),
        eta * float(se_ln[1]),
        k,
        k * se_lnk,
        corr,
        offsets,
        rms,
        float(np.sqrt(np.mean(r**2))),
        full,
        a0,
        b0,
        None,
        n_ind,
        evals,
        cov,
        dof,
        n_cl,
        leverage,
        lag_s,
        lag_se,
        fit_lag,
        edge,
    )


#: the fitted lag's unit inside the least squares (its steps and scale are then like ln To's)
LAG_UNIT_S = 1e-3


class Advance:
    """``x(t + a)`` for any advance ``a`` (s) of a record: exact for a band-limited one (a
    phase ramp e^{j w a} on its spectrum). The straight line through the record's ends is
    taken out first and advanced exactly, so the record's ends meet the zero padding without
    a jump (no ringing); within ``a`` of the ends the result is not the record's."""

    def __init__(self, x: np.ndarray, fs_hz: float) -> None:
        x = np.asarray(x, dtype=float)
        self.n = len(x)
        self.fs = fs_hz
        self.x0 = float(x[0])
        self.slope = float(x[-1] - x[0]) / max(1, self.n - 1)
        self.k = np.arange(self.n, dtype=float)
        self.nfft = scipy.fft.next_fast_len(2 * self.n, real=True)
        self.spec = scipy.fft.rfft(x - self.x0 - self.slope * self.k, self.nfft)
        self.w = 2 * math.pi * scipy.fft.rfftfreq(self.nfft, 1.0 / fs_hz)

    def __call__(self, advance_s: float) -> np.ndarray:
        y = scipy.fft.irfft(self.spec * np.exp(1j * self.w * advance_s), self.nfft)[: self.n]
        return y + self.x0 + self.slope * (self.k + advance_s * self.fs)


def _cycle_labels(seg: Segment, samples: np.ndarray, base: int) -> np.ndarray:
    """The cycle (numbered from ``base``) each of a segment's kept samples lies in."""
    per = (seg.stop - seg.start) / seg.n_cycles
    return base + np.minimum(((samples - seg.start) / per).astype(int), seg.n_cycles - 1)


@dataclass
class PathScan:
    """The fit at each trial bandwidth of the angle path (``fit_dahl_path``)."""

    cutoff_hz: list[float]
    residual_rms_Nm: list[float]
    To_Nm: list[float]
    eta_per_Nm: list[float]
    best: int

    def envelope(self, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
        """How far (ln To, ln eta, ln eta To^2) move from the best fit's over the stretch of the
        scan whose residual rms is within ``tolerance`` (a fraction) of the least: the path
        choices the torque cannot tell from the best. Between grid points the residual and the
        estimates are interpolated linearly in ln cutoff. Returns (down, up), each >= 0."""
        r = np.asarray(self.residual_rms_Nm, float)
        ln = np.column_stack(
            [
                np.log(self.To_Nm),
                np.log(self.eta_per_Nm),
                2 * np.log(self.To_Nm) + np.log(self.eta_per_Nm),
            ]
        )
        limit = r[self.best] * (1 + tolerance)
        reached = [ln[self.best]]
        for direction in (-1, 1):
            i = self.best
            while 0 <= i + direction < len(r):
                j = i + direction
                if r[j] <= limit:
                    reached.append(ln[j])
                    i = j
                    continue
                reached.append(ln[i] + (limit - r[i]) / (r[j] - r[i]) * (ln[j] - ln[i]))
                break
        v = np.array(reached) - ln[self.best]
        return np.maximum(-v.min(axis=0), 0.0), np.maximum(v.max(axis=0), 0.0)


def fit_dahl_path(
    theta_rad: np.ndarray,
    torque_Nm: np.ndarray,
    segments: list[Segment],
    fs_hz: float,
    *,
    smooth_hz: float,
    cutoffs_hz: list[float],
    step: int = 1,
    independent_every: int = 1,
    drop_cycle: int | None = None,
    start: tuple[float, ...] | None = None,
    lag_term_Nm: np.ndarray | None = None,
    max_lag_s: float = 0.0,
) -> tuple[DahlFit, PathScan]:
    """``fit_dahl`` along the measured angle low-passed at each of ``cutoffs_hz``; the fit that
    explains the torque best (least residual) is returned, with the scan.

    Why a choice: eq. 5.2 is a hysteresis, so the torque depends on every reversal of the
    angle. The platform really moves in the servo's band (its response to the sensor's noise,
    the steps of the command DAC), and the bearing follows those small reversals; above it the
    instrumentation channel shows mostly its own noise, which is no motion at all. Too low a
    cutoff drops real reversals, too high a one adds false ones; both spoil the fit, so the
    residual finds the band the data support. ``lag_term_Nm``, ``max_lag_s``: the angle's lag
    is fitted at every bandwidth too (``fit_dahl``)."""
    if not cutoffs_hz:
        raise ValueError("no trial cutoffs for the angle path")
    cutoffs_hz = sorted(float(c) for c in cutoffs_hz)
    fits: list[DahlFit] = []
    guess = start
    for fc in cutoffs_hz:
        path = lowpass(theta_rad, fs_hz, fc)
        fit = fit_dahl(
            path,
            torque_Nm,
            segments,
            fs_hz,
            smooth_hz=smooth_hz,
            step=step,
            independent_every=independent_every,
            start=guess,
            drop_cycle=drop_cycle,
            lag_term_Nm=lag_term_Nm,
            max_lag_s=max_lag_s,
        )
        fit.path_cutoff_hz = float(fc)
        fits.append(fit)
        guess = (fit.To_Nm, fit.eta_per_Nm, fit.lag_s)
    best = int(np.argmin([f.residual_rms_total_Nm for f in fits]))
    if 0 < best < len(fits) - 1:
        # refine: the least residual between the best's neighbours (Brent's bounded search in
        # log cutoff), so the choice moves continuously with the data rather than by grid steps
        tried: dict[float, DahlFit] = {}

        def resid(x: float) -> float:
            fit = fit_dahl(
                lowpass(theta_rad, fs_hz, math.exp(x)),
                torque_Nm,
                segments,
                fs_hz,
                smooth_hz=smooth_hz,
                step=step,
                independent_every=independent_every,
                start=(fits[best].To_Nm, fits[best].eta_per_Nm, fits[best].lag_s),
                drop_cycle=drop_cycle,
                lag_term_Nm=lag_term_Nm,
                max_lag_s=max_lag_s,
            )
            fit.path_cutoff_hz = math.exp(x)
            tried[x] = fit
            return fit.residual_rms_total_Nm

        lo, hi = math.log(cutoffs_hz[best - 1]), math.log(cutoffs_hz[best + 1])
        opt = scipy.optimize.minimize_scalar(
            resid, bounds=(lo, hi), method="bounded", options={"xatol": 0.01, "maxiter": 12}
        )
        x = min(tried, key=lambda k: tried[k].residual_rms_total_Nm)
        fit = tried[x]
        del opt
        if fit.residual_rms_total_Nm < fits[best].residual_rms_total_Nm:
            fc = math.exp(x)
            order = int(np.searchsorted(cutoffs_hz, fc))
            cutoffs_hz = list(cutoffs_hz[:order]) + [fc] + list(cutoffs_hz[order:])
            fits.insert(order, fit)
            best = order
    scan = PathScan(
        [float(c) for c in cutoffs_hz],
        [f.residual_rms_total_Nm for f in fits],
        [f.To_Nm for f in fits],
        [f.eta_per_Nm for f in fits],
        best,
    )
    return fits[best], scan


# ---------------------------------------------------------------------------- the angle's lag
#: a command line used to measure the lag is at least this fraction of the fundamental's amplitude
LINE_MIN = 1e-5
#: ... and at least this many times the command's power in the bins around it (an isolated line)
LINE_ISOLATION = 100.0


@dataclass
class LagMeasurement:
    """How far the recorded angle lags the recorded torque input (``measure_lag``)."""

    lag_s: float
    se_s: float
    dof: int  # cycles less one (the jackknife's)
    frequencies_hz: list[float]  # the command's lines used
    lags_s: list[float]  # the lag each line gives alone
    lag_se_s: list[float]
    n_cycles: int


def measure_lag(
    cmd: np.ndarray,
    angle: np.ndarray,
    drive: np.ndarray,
    fs_hz: float,
    freq_hz: float,
    segments: list[Segment],
    response: Callable[[np.ndarray], np.ndarray],
    *,
    min_hz: float,
    max_hz: float,
    max_lines: int = 8,
    max_se_rad: float = 0.1,
    drop_cycle: int | None = None,
    lines_hz: list[float] | None = None,
) -> LagMeasurement:
    """The lag (s) of the recorded ``angle`` behind the recorded ``drive`` (the power-amplifier
    input), measured at the command's lines between ``min_hz`` and ``max_hz``.

    The sinusoidal command is a staircase (a DAC updated a whole number of times a cycle), so
    besides the fundamental it carries lines at the harmonics of the drive frequency around the
    update rate. Above the servo band the platform there is a rigid body: ``response(w)`` (the
    data sheet's angle per unit drive, Kp Km / Ra / (-I w^2 + j D w), eq. 3.23-3.27) gives its
    phase, and what the record shows beyond it is the instruments' lag: the instrumentation
    channel's filters (eq. 3.22) and the motor's La/Ra, which the data sheet does not give.

    The transfer function drive -> angle at a line is taken with the command as the instrument
    (sum over cycles of A conj(C) / sum of D conj(C)), so neither the sensor's noise (which the
    servo feeds into the drive) nor any disturbance uncorrelated with the command biases it.
    Each kept cycle of every segment is one determination; a delete-one-cycle jackknife gives
    the errors. The lines (the ``max_lines`` strongest in the command) are combined by weighted
    least squares in ``-phase = w lag``; ``se_s`` is the jackknife's of that combination,
    raised by the lines' scatter about it when they disagree beyond their errors. ``drop_cycle``
    leaves the kept cycle of that index out of every segment (a jackknife replicate);
    ``lines_hz`` then names the lines to use (the full record's), none chosen or dropped."""
    per = fs_hz / freq_hz
    n_per = int(round(per))
    starts = [
        int(round(s.start + c * per))
        for s in segments
        for c in range(s.n_cycles)
        if c != drop_cycle
    ]
    starts = [a for a in starts if a + n_per <= len(cmd)]
    if len(starts) < 3:
        raise ValueError(f"{len(starts)} cycles are too few to measure the angle's lag")
    if max_hz > 0.5 * fs_hz:
        raise ValueError(f"lines up to {max_hz:g} Hz are beyond half the rate ({0.5 * fs_hz:g} Hz)")
    if max_hz < min_hz + freq_hz:
        raise ValueError(f"no harmonic of {freq_hz:g} Hz between {min_hz:g} and {max_hz:g} Hz")
    # The lines as bins of the n_per-sample window. The fundamental, 1e4 times the lines in the
    # angle, must not leak into them: all three records are high-passed alike first (a filter
    # common to the three cancels in the ratio below).
    f_bin = fs_hz / n_per
    h_lo, h_hi = int(math.ceil(min_hz / f_bin)), int(math.floor(max_hz / f_bin))
    harm = np.arange(h_lo, h_hi + 1)
    sos = scipy.signal.butter(4, 0.5 * min_hz, btype="highpass", fs=fs_hz, output="sos")
    c_hp, a_hp, d_hp = (
        scipy.signal.sosfiltfilt(sos, np.asarray(x, dtype=float)) for x in (cmd, angle, drive)
    )
    blocks = np.array(starts)[:, None] + np.arange(n_per)[None, :]
    # the lines are chosen on the plain transform; measured through a Hann window, whose far
    # sidelobes fall fast (a transient of an amplitude step near a window's end stays out).
    # Each line is a bin of the cycle's DFT, sum_n x[n] exp(-2 pi j n k / n_per): one FFT per
    # record (a product with the lines' exponentials took 0.2 s a call, 14 calls a run)
    hann = 0.5 - 0.5 * np.cos(2 * math.pi * np.arange(n_per) / n_per)
    c_blocks = c_hp[blocks]
    around_c = scipy.fft.rfft(c_blocks, axis=1)
    C = around_c[:, harm]
    Ch, A, D = (
        scipy.fft.rfft(hann * x, axis=1)[:, harm] for x in (c_blocks, a_hp[blocks], d_hp[blocks])
    )
    # the lines the command really carries: the strongest, well above its floor, above
    # LINE_MIN of its fundamental (a smooth command's numerical dust is no excitation), and
    # isolated: LINE_ISOLATION times the median of the bins 3-10 away on either side. A smooth
    # sinusoid's leakage (its amplitude steps, the high-pass's transients) is a continuum
    # falling with frequency, whose bins just above min_hz pass any plain threshold; the
    # bearing's harmonics of the fundamental ride in the same bins, so the "line" would
    # measure the nonlinearity, not the lag (issue 38 item 7: 8.9 ms read for 3.5 ms).
    power = np.mean(np.abs(C) ** 2, axis=0)
    order = np.argsort(power)[::-1]
    floor = float(np.median(power))
    x = np.asarray(cmd, dtype=float)[blocks]
    fund = float(np.mean(np.abs(x @ np.exp(-2j * math.pi * np.arange(n_per) / n_per)) ** 2))
    near = np.concatenate([np.arange(-10, -2), np.arange(3, 11)])
    around = np.mean(np.abs(around_c) ** 2, axis=0)  # every bin of the window
    local = np.array(
        [float(np.median(around[np.clip(k + near, 1, len(around) - 1)])) for k in harm]
    )
    strong = [
        int(i)
        for i in order[:max_lines]
        if power[i] > max(100.0 * floor, LINE_MIN**2 * fund, LINE_ISOLATION * local[i])
    ]
    if lines_hz is not None:
        strong = [int(np.argmin(np.abs(harm * f_bin - f))) for f in lines_hz]
        max_se_rad = math.inf
    if not strong:
        raise ValueError(
            f"the command carries no line between {min_hz:g} and {max_hz:g} Hz to measure the "
            f"angle's lag at (a smooth drive: no DAC staircase in band)"
        )
    w = 2 * math.pi * harm[strong] * f_bin
    model = response(w)
    num = A[:, strong] * np.conj(Ch[:, strong])  # cycles x lines
    den = D[:, strong] * np.conj(Ch[:, strong])

    def lags(keep: np.ndarray) -> np.ndarray:
        H = num[keep].sum(axis=0) / den[keep].sum(axis=0)
        return -np.angle(H / model) / w

    n = len(starts)
    every = np.ones(n, bool)
    full = lags(every)
    jack = np.empty((n, len(strong)))
    for i in range(n):
        keep = every.copy()
        keep[i] = False
        jack[i] = lags(keep)
    se_line = np.sqrt((n - 1) / n * np.sum((jack - jack.mean(axis=0)) ** 2, axis=0))
    good = se_line * w < max_se_rad
    if not np.any(good):
        raise ValueError(
            f"the command's lines between {min_hz:g} and {max_hz:g} Hz are too weak in the angle and "
            f"the drive to measure the angle's lag (phase errors over {max_se_rad:g} rad)"
        )
    wt = np.where(good, 1.0 / np.maximum(se_line, 1e-12) ** 2, 0.0)
    wt /= wt.sum()
    lag = float(wt @ full)
    jack_c = jack @ wt
    se = float(np.sqrt((n - 1) / n * np.sum((jack_c - jack_c.mean()) ** 2)))
    m = int(np.count_nonzero(good))
    if m > 1:
        chi2 = float(np.sum(((full - lag) / se_line)[good] ** 2))
        se *= max(1.0, math.sqrt(chi2 / (m - 1)))  # the Birge ratio: lines that disagree
    return LagMeasurement(
        lag,
        se,
        n - 1,
        [float(f) for f in harm[strong][good] * f_bin],
        [float(x) for x in full[good]],
        [float(x) for x in se_line[good]],
        n,
    )
