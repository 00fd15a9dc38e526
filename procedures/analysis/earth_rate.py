"""The earth-rate fit as a multi-position torque-to-balance test: torquer scale factor K_TO,
fixed drift d, g-sensitive drifts along the platform axes and the table base's azimuth offset,
each with a 95 % interval and a verdict on whether the design resolves it (thesis II C.1.a(1),
II B.10; IEEE Std 836 static multi-position test; the CIGTF torque-to-balance test).

In Mode 3 the caging loop holds the pickoff near null, and the torquer output balances what
the float would otherwise integrate (II C.1.a(8), with the elastic restraint's share):

    -K_TO V_T = Omega_i + d + g_x f_x + g_y f_y + g_z f_z - sigma / (h/k)

``Omega_i`` the earth rate along the channel's input axis and ``f`` the specific force (g) on
the platform axes at the station's table tilt and spindle angle (``platform_frame``, Ch. II
C.4.b), ``sigma`` the standing pickoff angle and ``h/k`` the float's restraint time constant:
a proportional-only caging loop (XRD) leaves a standing angle whose restraint torque
balances part of the rate without torquer current, so the apparent scale factor would read
K_TO (1 + 1/(G_p h/k)) (+0.19 % on XRD) if it were left out.

At a fixed azimuth offset the model is linear in (1/K_TO, d/K_TO, g/K_TO); the horizontal
channels (X, Y, XRD) profile the offset (the spindle turns their input axes through the earth
rate's horizontal component), Z takes their mean offset. A term linear in the visiting order
keeps a slow drift trend out of the rest.

**Intervals.** Station means are not independent: the gyros' flicker drift and the caging
loops' slow tails carry over from one station to the next. The fit is generalised least
squares with AR(1) station errors in visiting order (``ar1_gls``), the correlation rho a
nuisance judged by its restricted likelihood and integrated out of the covariance, and the
intervals use Student's t with the fit's residual degrees of freedom. Figures derived from the
coefficients (K_TO, d, g) take the delta method. A figure whose interval is wider than its magnitude or whose estimate
correlates by more than 0.95 with a better-determined one (relative to its value) is not
resolved (``procedures.analysis.intervals``): Z's input axis never reverses on a 0-90 deg table
(its rate spans Omega sin(lat) .. Omega, and sin t, cos t and 1 are nearly dependent over
0-90 deg), so its fixed drift and its g-drift along z are confounded with its scale factor
(correlation 0.99) and reported unresolved, while the scale factor's marginal interval stays.
Measured on synthetic stations with AR(1) (rho 0.6, 0.9) and 1/f errors, coverage of the 95 %
intervals 0.89-0.99 (``tests/procedures/test_earth_rate_stopwatch.py``); on 98 sim rigs with
random configurations and noise levels, K_TO 383/392, horizontal fixed drifts 283/294
(``bench/earth_rate_coverage.py``, docs/procedures/earth-rate.md).

Plain arrays and station dicts in, ``ChannelFit`` out; no rig. The procedure that takes the
stations is ``procedures.calibrations.earth_rate``; the report is ``procedures.reports.earth_rate``.
Site latitude, earth rate, the restraint time constants and the pickoff scale factors are
arguments (the rig's data sheet), never constants here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.stats

from drivers.rig_datasheet import GYRO_CHANNELS, PICKOFF_SCALE_TOLERANCE
from procedures.analysis.allan import FLICKER_FLOOR
from procedures.analysis.intervals import Estimate, judged
from procedures.stepresult import StepResult

URAD = 1e-6
RHO_GRID = np.linspace(0.0, 0.95, 39)
#: the platform axis each channel's input axis lies on (DESIGN.md section 3: X-Y gyro -> X, Y;
#: X-Z gyro -> Z and the redundant X, XRD)
INPUT_AXIS = {"X": 0, "Y": 1, "Z": 2, "XRD": 0}
HORIZONTAL = ("X", "Y", "XRD")
G_AXES = ("x", "y", "z")


@dataclass(frozen=True)
class Station(StepResult):
    """One station's step result: the table's position read back (deg), the settled torquer
    means ``V`` (V) with their standard errors ``se`` and the pickoff means ``pickoff_V`` (for
    the restraint term), per channel; its averaging window ``t`` and settling time (rig s)."""

    tilt: float
    spindle: float
    V: dict[str, float]
    pickoff_V: dict[str, float] | None = None
    se: dict[str, float] = field(default_factory=dict)
    t: tuple[float, float] | None = None
    settle_s: float | None = None


def platform_frame(
    tilt_deg: float, spindle_deg: float, offset_deg: float, latitude_deg: float, earth_rate: float
) -> tuple[np.ndarray, np.ndarray]:
    """(earth rate rad/s, specific force g) on the platform X, Y, Z axes (Ch. II C.4.b).

    Local east-north-up; the table base is turned ``offset`` from north; its east-west shaft
    tilts the spindle from vertical toward north by ``tilt``; the spindle (platform Z) turns the
    platform by ``spindle``. At tilt 0 platform X points ``spindle - offset`` from north toward
    west. The specific force is the support's reaction, +1 g up."""
    t, s, a = math.radians(tilt_deg), math.radians(spindle_deg), -math.radians(offset_deg)
    north, west, up = (
        np.array([0.0, 1.0, 0.0]),
        np.array([-1.0, 0.0, 0.0]),
        np.array([0.0, 0.0, 1.0]),
    )
    xb = north * math.cos(a) + west * math.sin(a)
    yb = -north * math.sin(a) + west * math.cos(a)
    zt = up * math.cos(t) + xb * math.sin(t)
    xt = xb * math.cos(t) - up * math.sin(t)
    axes = np.vstack(
        [xt * math.cos(s) + yb * math.sin(s), -xt * math.sin(s) + yb * math.cos(s), zt]
    )
    lat = math.radians(latitude_deg)
    return axes @ (earth_rate * np.array([0.0, math.cos(lat), math.sin(lat)])), axes @ up


@dataclass
class ChannelFit:
    channel: str
    kto: Estimate  # urad/s per V
    drift: Estimate  # fixed drift, urad/s
    g_drift: dict[str, Estimate]  # g-sensitive drift along platform x, y, z, urad/s per g
    psi0_deg: float | None  # the table base's azimuth offset this channel sees (horizontal ones)
    correlation: dict[str, float]  # the largest |correlation| of each figure with another, signed
    tilt_deg: np.ndarray
    spindle_deg: np.ndarray
    volts: np.ndarray
    predicted: np.ndarray
    residual_rms_V: float
    dof: int
    restraint_correction: float  # relative change of K_TO made by the standing-pickoff term
    figures: dict[str, Estimate] = field(default_factory=dict)
    psi0_sd_deg: float | None = None  # psi0's standard uncertainty (horizontal channels)

    @property
    def kto_urad_per_s_per_V(self) -> float:
        return self.kto.value

    @property
    def drift_urad_per_s(self) -> float:
        return self.drift.value


def _prais_winsten(X: np.ndarray, v: np.ndarray, rho: float) -> tuple[np.ndarray, np.ndarray]:
    """The AR(1)-whitened regression: row 0 scaled by sqrt(1 - rho^2), rows k by x_k - rho x_(k-1)."""
    Xw, vw = X.copy(), v.copy()
    Xw[1:], vw[1:] = X[1:] - rho * X[:-1], v[1:] - rho * v[:-1]
    c = math.sqrt(1.0 - rho * rho)
    Xw[0], vw[0] = X[0] * c, v[0] * c
    return Xw, vw


@dataclass(frozen=True)
class AR1Fit:
    """``ar1_gls``'s result: the coefficients at rho's restricted-likelihood maximum, the
    residuals of the untransformed model, their covariance marginal over rho, and rho."""

    coef: np.ndarray
    resid: np.ndarray
    cov: np.ndarray
    rho: float


def ar1_gls(X: np.ndarray, v: np.ndarray) -> AR1Fit:
    """Generalised least squares for station errors that wander from one station to the next.

    The errors are taken as AR(1) in visiting order, e_k = rho e_(k-1) + w_k (a gyro's flicker
    drift and the caging loops' slow tails carry over between neighbouring stations), whitened
    by the Prais-Winsten transform, which keeps the first station. rho is a nuisance, judged by
    its restricted (REML) likelihood

        L(rho) = -(n-p)/2 ln(RSS_rho / (n-p)) + 1/2 ln(1 - rho^2) - 1/2 ln det(X_rho^T X_rho)

    (Harville 1977; Cheang and Reinsel 2000 for AR(1) errors in regression): the plain
    likelihood's maximum sits low when p coefficients are fitted to n = 24 stations, and
    weighting by it, as below, covered AR(1) rho 0.6 errors' g-drifts only 77-85 %. A short record
    still leaves rho uncertain, so the covariance is marginal over it: the coefficients' mean
    squared error about the estimate, averaged over the rho grid with weights exp(L(rho)) (a flat
    prior on 0..0.95; the law of total variance, E[Cov | rho] + E[(b_rho - b_hat)(b_rho -
    b_hat)^T]). On such errors the 95 % intervals then cover 89-99 % at rho 0.3-0.9 and 99-100 %
    at rho 0 (``tests/procedures/test_earth_rate_stopwatch.py``)."""
    n, p = X.shape
    ll, coefs, covs = [], [], []
    for r in RHO_GRID:
        Xw, vw = _prais_winsten(X, v, float(r))
        coef, *_ = np.linalg.lstsq(Xw, vw, rcond=None)
        e = vw - Xw @ coef
        rss = float(e @ e)
        ll.append(
            -0.5 * (n - p) * math.log(max(rss, 1e-300) / max(1, n - p))
            + 0.5 * math.log(1.0 - r * r)
            - 0.5 * np.linalg.slogdet(Xw.T @ Xw)[1]
        )
        coefs.append(coef)
        covs.append(np.linalg.inv(Xw.T @ Xw) * rss / max(1, n - p - 1))
    ll_arr = np.array(ll)
    k = int(np.argmax(ll_arr))
    coef = coefs[k]
    w = np.exp(ll_arr - ll_arr[k])
    w /= w.sum()
    cov = sum(
        (wi * (c + np.outer(b - coef, b - coef)) for wi, c, b in zip(w, covs, coefs)),
        np.zeros((p, p)),
    )
    return AR1Fit(coef, v - X @ coef, cov, float(RHO_GRID[k]))


def _design(
    ch: str,
    tilt: np.ndarray,
    spindle: np.ndarray,
    latitude_deg: float,
    earth_rate: float,
    order: np.ndarray,
) -> np.ndarray:
    """Columns: P, Q (the earth rate's horizontal part on the input axis with the base at offset
    0 and at 90 deg: at offset o it is cos(o) P + sin(o) Q), 1, f_x, f_y, f_z (g), order.

    The earth rate's vertical part on the input axis is Omega sin(lat) f_i: the same column as
    the g-drift along the input axis (both follow "up"), so it is not a column of its own; the
    scale factor comes from the horizontal part, and g_i is what is left of f_i's coefficient."""
    rows = []
    for t, s in zip(tilt, spindle):
        w0, f = platform_frame(float(t), float(s), 0.0, latitude_deg, earth_rate)
        w90, _ = platform_frame(float(t), float(s), 90.0, latitude_deg, earth_rate)
        vert = earth_rate * math.sin(math.radians(latitude_deg)) * f
        i = INPUT_AXIS[ch]
        rows.append([w0[i] - vert[i], w90[i] - vert[i], 1.0, *f])
    cols = np.array(rows)
    # rounding leaves 1e-17 where a projection is zero (Q on Z, f at tilt 0): exactly zero
    scale = np.array([earth_rate, earth_rate, 1.0, 1.0, 1.0, 1.0])
    cols[np.abs(cols) < 1e-12 * scale] = 0.0
    k = np.asarray(order, float)
    return np.column_stack([cols, k - k.mean()])


def _identifiable(X: np.ndarray) -> np.ndarray:
    """Columns the stations vary independently, in order (a column that is constant or a
    combination of earlier ones, e.g. f_z at tilt 0 only, or Q on Z, is left out and what it
    carries is reported unresolved)."""
    unit = X / np.maximum(np.linalg.norm(X, axis=0), 1e-300)
    keep: list[int] = []
    for j in range(X.shape[1]):
        if np.linalg.matrix_rank(unit[:, keep + [j]], tol=1e-6) == len(keep) + 1:
            keep.append(j)
    mask = np.zeros(X.shape[1], bool)
    mask[keep] = True
    return mask


COLUMNS = ("P", "Q", "one", "x", "y", "z", "order")
#: the bound on the restraint term's relative error from the data sheet's h/k (another unit of the
#: type: the h/k of the thesis's four channels span 424-1072 s)
RESTRAINT_UNCERTAINTY = 0.2


def restraint_bound(pickoff_rel_uncertainty: float = PICKOFF_SCALE_TOLERANCE) -> float:
    """The restraint term sigma / (h/k), sigma = V_g / K_g, is off by the factor 1 / ((1 + e_K)
    (1 + e_h)) for relative errors e_K of K_g and e_h of h/k: at most 1 / ((1 - u_K)(1 - u_h)) - 1
    for bounds u_K (the stopwatch's relative half-width, or by default ``PICKOFF_SCALE_TOLERANCE``
    for the data sheet's value: ``procedures.params.pickoff_scale_rel_half_width``) and u_h =
    ``RESTRAINT_UNCERTAINTY``."""
    return 1.0 / ((1.0 - min(pickoff_rel_uncertainty, 0.5)) * (1.0 - RESTRAINT_UNCERTAINTY)) - 1.0


def operating_instability(rate_resid: np.ndarray) -> float:
    """The run-to-run spread of a run's mean drift, from the run itself (same units as given).

    A run measures the fixed drift plus the gyro's random drift averaged over the run. For a
    bias-instability (flicker) process that average does not settle with a longer run: its
    run-to-run spread is about the Allan deviation at the run's length, which for flicker is
    the flat floor already reached at a fraction of it (IEEE Std 952 Annex C). Here: the
    largest overlapping Allan deviation of the stations' residual rates (visiting order) over
    averaging times of 2 stations to a third of them. White station noise raises the short
    ones and the fit's own terms (constant, trend) absorb part of the wander from the long
    ones, so the largest is the least biased low; it is still a floor, not a bound. On 50 sim
    rigs with the default random drift (bias instability 0.02 urad/s) and no bias-instability
    figure, the horizontal channels' fixed-drift intervals covered 125/150 with the Allan
    deviation at a third of the run alone, 138/150 with this (``bench/earth_rate_coverage.py``)."""
    r = np.asarray(rate_resid, float)
    c = np.concatenate([[0.0], np.cumsum(r)])
    best = 0.0
    for m in range(2, len(r) // 3 + 1):
        y = (c[m:] - c[:-m]) / m  # means of m consecutive stations
        d = y[m:] - y[:-m]
        if len(d):
            best = max(best, float(np.sqrt(0.5 * np.mean(d * d))))
    return best


#: the span the fixed drift stands for (s): the gyro's mean drift over about 12 days, the life of
#: a calibration between lab checks, not the mean over the run that measured it
DRIFT_SPAN_S = 1e6
#: a run this long or longer is taken if the stations do not say when they were averaged (s):
#: the shorter the run the wider its mean wanders, so a guess errs wide
DEFAULT_RUN_S = 1000.0


def mean_wander(run_s: float, span_s: float = DRIFT_SPAN_S) -> float:
    """How far a run's mean drift wanders from the mean over ``span_s``, per Allan floor.

    Flicker (bias-instability) drift, one-sided PSD h/f, has the same Allan variance
    2 ln 2 h at every averaging time (IEEE Std 952 Annex C), while the mean over a run of
    length T differs from the mean over a span S >> T by the flicker between 1/S and 1/T,
    variance h ln(S / T): the run-to-run spread is the Allan floor times
    sqrt(ln(S / T) / (2 ln 2)), at least the floor itself. At T = 4700 s (the default
    earth-rate run) and S = ``DRIFT_SPAN_S`` that is 1.97. The sim rig's flicker bank (1/f
    above 1e-5 Hz, flat below) spreads a 4720 s mean by 1.20 B = 1.81 Allan floors (300
    records): by this formula, as much as 1/f reaching 2e-6 Hz. With the Allan floor alone the
    horizontal channels' fixed drifts of 40 drawn rigs covered 111 of 120, with this 115
    (``bench/coverage_all.py``, issue 38; docs/procedures/earth-rate.md)."""
    return math.sqrt(max(math.log(span_s / max(run_s, 1e-9)) / (2.0 * math.log(2.0)), 1.0))


def run_span_s(stations: list[Station]) -> float:
    """From the first station's averaging start to the last one's end (rig s), or
    ``DEFAULT_RUN_S`` if a station does not say."""
    times = [s.t for s in stations if s.t is not None]
    if not times or len(times) < len(stations):
        return DEFAULT_RUN_S
    return max(max(end for _, end in times) - min(start for start, _ in times), 1.0)


def fit_channel(
    ch: str,
    stations: list[Station],
    *,
    latitude_deg: float,
    earth_rate_rad_per_s: float,
    restraint_s: float | None = None,
    pickoff_mV_per_urad: float | None = None,
    offset_deg: float | None = None,
    offset_sd_deg: float = 0.0,
    instability_urad_per_s: float = 0.0,
    pickoff_rel_uncertainty: float = PICKOFF_SCALE_TOLERANCE,
) -> ChannelFit:
    """One channel's multi-position fit from the stations (``Station``: ``tilt``, ``spindle``
    deg, the settled torquer means ``V`` and, for the restraint term, the pickoff means
    ``pickoff_V``, per channel, in visiting order).

    Linear in the coefficients b of ``V = b_P P + b_Q Q + b_1 + b_x f_x + b_y f_y + b_z f_z
    [+ b_o order] - r / K_TO`` (``_design``; r the restraint rate sigma/(h/k), moved to the
    left at the current K_TO and re-fitted once): with the base at offset o, b_P = -cos(o)/K_TO,
    b_Q = -sin(o)/K_TO, b_1 = -d/K_TO, b_k = -(g_k + Omega sin(lat) [k = input axis])/K_TO.
    A channel whose input axis the spindle does not turn (Z: no Q column) takes ``offset_deg``
    (the horizontal channels'): K_TO = -cos(o)/b_P, and the offset's standard uncertainty
    ``offset_sd_deg`` enters its variance through dK_TO/do = -K_TO tan(o).

    ``instability_urad_per_s``: the gyro's bias instability B where known (an earlier drift run,
    a data sheet): the fixed drift's interval carries the wander of a run's mean drift about the
    long-term mean (``mean_wander`` times the Allan floor, the larger of 0.664 B and the
    stations' own, ``operating_instability``); the restraint term's own uncertainty (data-sheet
    h/k and K_g of ``pickoff_rel_uncertainty``, ``restraint_bound``) is carried by K_TO's."""
    tilt = np.array([s.tilt for s in stations], float)
    spindle = np.array([s.spindle for s in stations], float)
    v = np.array([s.V[ch] for s in stations], float)
    n = len(stations)
    restraint = np.zeros(n)
    picked = [s.pickoff_V for s in stations]
    if restraint_s and pickoff_mV_per_urad and all(p is not None for p in picked):
        sigma_rad = (
            np.array([p[ch] for p in picked if p is not None]) / (pickoff_mV_per_urad * 1e-3) * URAD
        )
        restraint = sigma_rad / restraint_s
    X_all = _design(ch, tilt, spindle, latitude_deg, earth_rate_rad_per_s, np.arange(n))
    keep = _identifiable(X_all)
    X = X_all[:, keep]
    col = {name: int(np.sum(keep[:j])) for j, name in enumerate(COLUMNS) if keep[j]}
    if "P" not in col:
        raise ValueError(
            f"earth-rate {ch}: the stations do not turn the input axis through the earth rate's "
            f"horizontal part; add tilts or spindle angles"
        )
    has_q = "Q" in col
    if not has_q and offset_deg is None:
        offset_deg = 0.0
    lat = math.radians(latitude_deg)
    omega_v = earth_rate_rad_per_s * math.sin(lat)

    def figures_of(b: np.ndarray) -> dict[str, float]:
        """K_TO (urad/s/V), psi0 (deg), d (urad/s), g_k (urad/s/g) from the coefficients."""
        if has_q:
            k = 1.0 / math.hypot(b[col["P"]], b[col["Q"]])
            o = math.atan2(-b[col["Q"]], -b[col["P"]])
        else:
            o = math.radians(offset_deg or 0.0)
            k = -math.cos(o) / b[col["P"]]
        out = {"K_TO": k / URAD, "psi0": math.degrees(o), "drift": -b[col["one"]] * k / URAD}
        for a, name in zip(G_AXES, ("x", "y", "z")):
            if name in col:
                out[f"g_{a}"] = (
                    -b[col[name]] * k - (omega_v if INPUT_AXIS[ch] == G_AXES.index(a) else 0.0)
                ) / URAD
        return out

    fit = ar1_gls(X, v)
    k0 = figures_of(fit.coef)["K_TO"] * URAD
    if np.any(restraint):
        # the restraint rate enters as +r/K_TO: moved to the left at the current K_TO and fitted
        # again (r/K_TO is a per-mille term: two passes leave under 1e-9 of it)
        kto_now = k0
        for _ in range(3):
            fit = ar1_gls(X, v - restraint / kto_now)
            kto_now = figures_of(fit.coef)["K_TO"] * URAD
        correction = kto_now / k0 - 1.0
    else:
        correction = 0.0
    coef, resid = fit.coef, fit.resid
    p = X.shape[1]
    dof = max(1, n - p - 1)
    q = float(scipy.stats.t.ppf(0.975, dof))
    vals = figures_of(coef)
    names = [k for k in vals if k != "psi0"]
    # delta method, numerically: the figures' Jacobian in the coefficients
    J = np.zeros((len(vals), p))
    keys = list(vals)
    for j in range(p):
        h = 1e-6 * max(abs(coef[j]), 1e-12)
        up, dn = coef.copy(), coef.copy()
        up[j] += h
        dn[j] -= h
        fu, fd = figures_of(up), figures_of(dn)
        J[:, j] = [(fu[k] - fd[k]) / (2 * h) for k in keys]
    C = J @ fit.cov @ J.T
    # the fixed drift is not this run's drift: the gyro's random drift averaged over the run
    # departs from its long-term mean by the flicker's wander below 1/run, added as an error of
    # its own: the Allan floor (``operating_instability``, or the known B's) times ``mean_wander``
    floor = max(operating_instability(resid * vals["K_TO"]), FLICKER_FLOOR * instability_urad_per_s)
    op = floor * mean_wander(run_span_s(stations))
    C[keys.index("drift"), keys.index("drift")] += op**2
    # the restraint term is good to +-restraint_bound of itself: a bound, so a rectangular
    # distribution's standard uncertainty, a / sqrt(3) (GUM 4.3.7)
    bound = restraint_bound(pickoff_rel_uncertainty)
    C[keys.index("K_TO"), keys.index("K_TO")] += (
        bound / math.sqrt(3.0) * correction * vals["K_TO"]
    ) ** 2
    if not has_q:
        # the base's azimuth offset is the horizontal channels' (Ch. II C.4.b: Z's input axis
        # leans toward the base's north by the tilt, so its earth rate is Omega (sin(lat) cos t
        # + cos(lat) cos(o) sin t)): K_TO = -cos(o)/b_P carries o's uncertainty as tan(o) d o
        o = math.radians(offset_deg or 0.0)
        C[keys.index("K_TO"), keys.index("K_TO")] += (
            vals["K_TO"] * math.tan(o) * math.radians(offset_sd_deg)
        ) ** 2
    sd = np.sqrt(np.maximum(np.diag(C), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):  # exact data: zero variances
        R = np.nan_to_num(C / np.outer(sd, sd))
    figures: dict[str, Estimate] = {}
    correlation: dict[str, float] = {}
    idx = {k: i for i, k in enumerate(keys)}
    # Of two figures the design confounds (|correlation| > 0.95) the one it leaves undetermined
    # is not resolved: each interval is marginal (the full covariance), so the better-determined
    # partner's stays valid (Z's K_TO within +-0.5-1.7 % while its fixed drift spans +-0.3 urad/s).
    rel = {k: q * sd[idx[k]] / max(abs(vals[k]), 1e-300) for k in names}
    for k in names:
        i = idx[k]
        others = [idx[m] for m in names if m != k]
        j = max(others, key=lambda m: abs(R[i, m])) if others else i
        correlation[k] = float(R[i, j]) if others else 0.0
        weaker = [idx[m] for m in names if m != k and rel[m] <= rel[k]]
        jw = max(weaker, key=lambda m: abs(R[i, m])) if weaker else i
        figures[k] = judged(
            vals[k],
            vals[k] - q * sd[i],
            vals[k] + q * sd[i],
            correlation=float(R[i, jw]) if weaker else 0.0,
            with_=keys[jw],
        )
    for a in G_AXES:
        if f"g_{a}" not in figures:
            figures[f"g_{a}"] = Estimate(
                math.nan,
                -math.inf,
                math.inf,
                False,
                "the stations do not vary the specific force along this axis",
            )
    return ChannelFit(
        ch,
        figures["K_TO"],
        figures["drift"],
        {a: figures[f"g_{a}"] for a in G_AXES},
        vals["psi0"] if has_q else None,
        correlation,
        tilt,
        spindle,
        v,
        v - resid,
        float(np.sqrt(np.mean(resid**2))),
        dof,
        correction,
        figures,
        float(sd[idx["psi0"]]) if has_q else None,
    )


def fit_earth_rate(
    stations: list[Station],
    *,
    latitude_deg: float,
    earth_rate_rad_per_s: float,
    restraint_s: dict[str, float] | None = None,
    pickoff_mV_per_urad: dict[str, float] | None = None,
    instability_urad_per_s: dict[str, float] | None = None,
    pickoff_rel_uncertainty: dict[str, float] | None = None,
) -> dict[str, ChannelFit]:
    """Every channel's fit from the stations in visiting order: the horizontal channels first
    (each profiles the base's azimuth offset), then Z at their mean offset. That offset's
    uncertainty is the larger of the channels' own standard uncertainties and their spread (a
    gyro's input axis misaligned on the platform turns its psi0, not the table's): no credit
    for averaging them."""

    def one(ch: str, offset: float | None, offset_sd: float = 0.0) -> ChannelFit:
        return fit_channel(
            ch,
            stations,
            latitude_deg=latitude_deg,
            earth_rate_rad_per_s=earth_rate_rad_per_s,
            restraint_s=(restraint_s or {}).get(ch),
            pickoff_mV_per_urad=(pickoff_mV_per_urad or {}).get(ch),
            offset_deg=offset,
            offset_sd_deg=offset_sd,
            instability_urad_per_s=(instability_urad_per_s or {}).get(ch) or 0.0,
            pickoff_rel_uncertainty=(pickoff_rel_uncertainty or {}).get(
                ch, PICKOFF_SCALE_TOLERANCE
            ),
        )

    fits = {ch: one(ch, None) for ch in HORIZONTAL}
    psi0 = [float(fits[c].psi0_deg or 0.0) for c in HORIZONTAL]
    offset_sd = max(
        max(float(fits[c].psi0_sd_deg or 0.0) for c in HORIZONTAL), float(np.std(psi0, ddof=1))
    )
    fits["Z"] = one("Z", float(np.mean(psi0)), offset_sd)
    return {ch: fits[ch] for ch in GYRO_CHANNELS}
