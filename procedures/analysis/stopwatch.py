"""The stopwatch numerics: K_g = dV_g / (dt dV_T K_TO) (thesis II C.1.a(6)) from a channel's
open-loop record, with the elastic restraint's correction. Arrays and the channel step's result
dict in, plain values out; no rig. The procedure (the steps, the null, the ramps) is
``procedures.calibrations.stopwatch``, whose docstring has the method; the report's table and
plot are ``procedures.reports.stopwatch``.

* ``crossing_times`` / ``crossing_interval``: one stopwatch reading, the time between the smoothed pickoff's
  crossings of the two levels of a ramp;
* ``restraint_fit``: tau = h/k from a least-squares fit of the whole open-loop record (step 4
  of the method);
* ``channel_result``: the readings corrected by x coth x, x = dt / (2 tau), their mean per
  down-up pair and the spread.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import scipy.linalg
import scipy.stats

from drivers.rig_datasheet import FLOAT_PARTNER, VISCOUS_COUPLING_TOLERANCE
from procedures.analysis.intervals import Estimate, from_stderr, judged
from procedures.stepresult import StepResult

#: why h/k is never a resolved figure (measured by bench/stopwatch_coverage.py over 50 rigs)
H_OVER_K_UNRESOLVED = (
    "not reported: the fit also carries the float partner's viscous coupling and the gyro's "
    "random drift (fitted h/k +2 to +13 % over 50 simulated rigs); its interval is for information"
)


class NoCrossing(ValueError):
    """The smoothed pickoff never crossed a level during a ramp."""


def slope(y: np.ndarray, dt: float) -> float:
    """Least-squares slope of equally spaced samples (V/s), NaNs skipped."""
    t = np.arange(len(y)) * dt
    ok = np.isfinite(y)
    t, y = t[ok], y[ok]
    tc = t - t.mean()
    return float(tc @ (y - y.mean()) / (tc @ tc))


def smooth(y: np.ndarray, n: int) -> np.ndarray:
    """Centred moving average over n samples (edges shortened)."""
    n = max(1, n)
    c = np.concatenate([[0.0], np.cumsum(y)])
    i = np.arange(len(y))
    lo = np.clip(i - n // 2, 0, len(y))
    hi = np.clip(i - n // 2 + n, 0, len(y))
    return (c[hi] - c[lo]) / (hi - lo)


def crossing_times(
    t: np.ndarray,
    vg: np.ndarray,
    lo: float,
    hi: float,
    direction: int,
    smooth_s: float,
    rate_hz: float,
) -> tuple[float, float]:
    """The times the smoothed pickoff crosses the ramp's first and second level (linear
    interpolation). Raises ``NoCrossing`` if it does not cross one of them."""
    s = smooth(vg, int(round(smooth_s * rate_hz)))
    first, second = (lo, hi) if direction > 0 else (hi, lo)

    def cross(level: float) -> float:
        beyond = (s - level) * direction >= 0
        idx = np.flatnonzero(beyond[1:] & ~beyond[:-1])
        if len(idx) == 0:
            raise NoCrossing(f"stopwatch: the pickoff never crossed {level:+.4f} V during a ramp")
        i = idx[0]
        return float(t[i] + (level - s[i]) / (s[i + 1] - s[i]) * (t[i + 1] - t[i]))

    return cross(first), cross(second)


def crossing_interval(
    t: np.ndarray,
    vg: np.ndarray,
    lo: float,
    hi: float,
    direction: int,
    smooth_s: float,
    rate_hz: float,
) -> float:
    """One stopwatch reading: the time between the two level crossings (``crossing_times``)."""
    t1, t2 = crossing_times(t, vg, lo, hi, direction, smooth_s, rate_hz)
    return t2 - t1


#: caging amplifiers without integral action (the redundant channel's, II C.1.a(8)): a first-order
#: loop of bandwidth omega_n
PROPORTIONAL_ONLY = frozenset({"XRD"})
#: what the partner-transient correction may be off by: this fraction of itself (a unit's h/c
#: against Table 3's) plus the model's residual against the simulated rig (0.02-0.03 %, measured
#: noise-free on the thesis rig and with K_g x0.75-0.83), a bound added to each side
PARTNER_MODEL_UNCERTAINTY = (VISCOUS_COUPLING_TOLERANCE, 3e-4)
#: a result made before the correction (no ``partner_factor`` per ramp): the transient's span
#: on drawn rigs, -0.29 % (a 250 urad ramp) .. +0.33 % (500 urad), as a bound on each side
PARTNER_TRANSIENT_BOUND = 0.0035


def partner_factors(
    t: np.ndarray,
    rate: np.ndarray,
    windows: list[tuple[float, float]],
    *,
    h_over_c: float,
    partner_h_over_c: float,
    partner_wn: float,
    partner_zeta: float,
    partner_proportional: bool = False,
) -> list[float]:
    """How much more (> 1) or less the uncaged float turns over each crossing window than
    ``rate`` (its torquer's rate, K_TO (V_T - V_T0), from rest at ``t[0]``) alone would turn it,
    because the float partner's caging loop answers the viscous cross-coupling (II C.4.d):

        sigma_a' = (f_a + (c/h)_b f_b) / (1 + (c/h)_a (c/h)_b),   sigma_b' = f_b - (c/h)_a sigma_a',
        f_b = -(2 zeta w sigma_b + w^2 int sigma_b)   (PI caging, II C.1.a(8); -w sigma_b proportional)

    (the cross-axis coupling of ``simhw.plant``). The ramp runs at K_TO dV_T only once the
    partner's loop has answered (f_b = (c/h)_a f_a); before that it runs slow by up to (c/h)_a
    (c/h)_b (2.4 % on the X-Y float), and the PI loop's overshoot then runs it fast, so a window
    reads low or high by where it sits in the transient: -0.29 % to +0.33 % on X for ramps of
    250-500 urad. The model is linear, integrated exactly (zero-order hold) on 0.05 s means of
    ``rate``.
    Each reading is divided by its window's factor."""
    ka, kb = 1.0 / h_over_c, 1.0 / partner_h_over_c
    w, z = partner_wn, partner_zeta
    kfb = np.array([-w, 0.0]) if partner_proportional else np.array([-2 * z * w, -w * w])
    # states (sigma_a, sigma_b, int sigma_b); sigma_a' = (f_a + kb f_b)/(1 + ka kb)
    g = 1.0 / (1.0 + ka * kb)
    fb_row = np.array([0.0, kfb[0], kfb[1]])
    A = np.zeros((3, 3))
    A[0] = kb * g * fb_row
    A[1] = fb_row - ka * A[0]
    A[2, 1] = 1.0
    B = np.array([g, -ka * g, 0.0])
    dt = float(np.median(np.diff(t)))
    u = np.nan_to_num(np.asarray(rate, float))
    alone = np.concatenate([[0.0], np.cumsum(u[:-1] * dt)])
    # the coupled float's departure from the torquer's own angle is slow (the partner's loop,
    # 0.1-1 rad/s): stepped on block means of about 0.05 s, then interpolated to the windows
    n = max(1, int(round(0.05 / dt)))
    m = len(u) // n * n
    ub = u[:m].reshape(-1, n).mean(axis=1)
    db = n * dt
    M = np.zeros((4, 4))
    M[:3, :3], M[:3, 3] = A * db, B * db
    E = scipy.linalg.expm(M)
    Ad, Bd = E[:3, :3], E[:3, 3]
    x = np.zeros(3)
    depart = np.zeros(len(ub) + 1)  # coupled minus alone at the block edges
    for i, ui in enumerate(ub):
        x = Ad @ x + Bd * ui
        depart[i + 1] = x[0]
    depart -= np.concatenate([[0.0], np.cumsum(ub * db)])
    tb = t[0] + np.arange(len(ub) + 1) * db
    out = []
    for t1, t2 in windows:
        i1, i2 = np.searchsorted(t, [t1, t2])
        i2 = min(i2, len(t) - 1)
        d_alone = alone[i2] - alone[i1]
        extra = float(np.interp(t[i2], tb, depart) - np.interp(t[i1], tb, depart))
        out.append(1.0 + extra / d_alone if d_alone else 1.0)
    return out


#: the restraint fit's robust covariance takes the residuals of this many seconds together
#: (the gyro's random drift is a slowly wandering rate: neighbouring increments share it)
CLUSTER_S = 30.0


def restraint_fit(
    t: np.ndarray,
    vg: np.ndarray,
    vt: np.ndarray,
    *,
    vt_null: float,
    vg0: float,
    dt_s: float,
    partner: np.ndarray | None = None,
    increment_s: float = 2.0,
) -> dict:
    """Least squares of the pickoff's increments over ``dt_s`` means,

        dV_g = a int(V_T - V_T0) + c dt - k int(V_g - V_g0) + b dV_gp,

    the restraint equation u' = r - u / tau (``procedures.calibrations.stopwatch``'s docstring,
    step 4) over each interval. ``partner`` is the pickoff of the channel sharing the float: its
    caging loop answers the viscous cross-coupling (II C.4.d) and, as it does, pushes this float
    at (c/h) sigma_p'; without that term the loop's slow unwinding after each ramp reads as
    restraint (h/k 2-4x too long). The increments, not the integrated record, are fitted so the
    errors are the rate noise of each interval, not its running sum; their covariance is
    cluster-robust over ``CLUSTER_S`` blocks (White's sandwich with the scores summed per block,
    small-sample factor G/(G-1)), and ``dof`` = G - 1 goes with it."""
    step = t[1] - t[0]
    n = max(1, int(round(dt_s / step)))
    m = len(t) // n * n

    def means(x: np.ndarray) -> np.ndarray:
        return np.nanmean(x[:m].reshape(-1, n), axis=1)

    tm, gm, vtm = means(t), means(vg), means(vt)
    # running integrals on the fine grid, differenced over each ``increment_s`` interval
    it = np.concatenate([[0.0], np.cumsum(((vtm[1:] + vtm[:-1]) / 2 - vt_null) * np.diff(tm))])
    ig = np.concatenate([[0.0], np.cumsum(((gm[1:] + gm[:-1]) / 2 - vg0) * np.diff(tm))])
    j = np.arange(0, len(tm), max(1, int(round(increment_s / dt_s))))
    cols = [np.diff(it[j]), np.diff(tm[j]), -np.diff(ig[j])]
    if partner is not None:
        pm = means(partner)
        ip = np.concatenate([[0.0], np.cumsum(((pm[1:] + pm[:-1]) / 2 - pm[0]) * np.diff(tm))])
        cols.append(np.diff(ip[j]))
    design = np.column_stack(cols)
    y = np.diff(gm[j])
    tm = tm[j]
    ok = np.all(np.isfinite(design), axis=1) & np.isfinite(y)
    X, y, tk = design[ok], y[ok], tm[1:][ok]
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    resid = y - X @ coef
    bread = np.linalg.inv(X.T @ X)
    block = np.floor((tk - tk[0]) / CLUSTER_S).astype(int)
    scores = np.zeros((block.max() + 1, X.shape[1]))
    np.add.at(scores, block, X * resid[:, None])
    groups = int(np.count_nonzero(np.any(scores != 0, axis=1)))
    cov = bread @ (scores.T @ scores) @ bread * groups / max(1, groups - 1)
    se = np.sqrt(np.diag(cov))
    return {
        "a": float(coef[0]),
        "a_se": float(se[0]),
        "c": float(coef[1]),
        "k": float(coef[2]),
        "k_se": float(se[2]),
        "b": float(coef[3]) if partner is not None else 0.0,
        "dof": max(1, groups - 1),
        "rms": float(np.sqrt(np.mean(resid**2))),
    }


@dataclass
class ChannelResult:
    channel: str
    kto: float
    kto_from: str
    readings: list[float]  # corrected stopwatch K_g per ramp, mV/urad
    naive: list[float]  # uncorrected
    repetitions: list[float]  # mean of each down-up pair
    asymmetry: float  # (up - down) / mean: a rate offset during the ramps
    kg: float
    kg_se: float
    spread: float
    kg_ls: float
    kg_ls_se: float
    tau_s: float | None
    tau_se: float | None
    correction: float  # mean (corrected / naive - 1)
    null_rate_urad_per_s: float
    restraint_dof: int = 1
    partner_correction: float = (
        0.0  # mean (reading with / without the partner transient's factor - 1)
    )
    partner_bound: float = PARTNER_TRANSIENT_BOUND  # relative bound on what is left of it
    #: (c/h)_a (c/h)_b of the channel's float (data sheet): the restraint fit's 1/k carries
    #: 1 + it (``tau_estimate``)
    coupling_carried: float = 0.0

    def kg_estimate(self, kto_rel_half_width: float | None) -> Estimate:
        """K_g with its 95 % interval: Student's t over the repetitions, combined in quadrature
        with the relative 95 % half-width of the K_TO used (K_g goes as 1 / K_TO), widened on
        each side by the bound on the float partner's caging transient left after its correction
        (``partner_factors``, ``PARTNER_MODEL_UNCERTAINTY``; ``PARTNER_TRANSIENT_BOUND`` for a
        result made without it): a bound, added to the statistical half-width. With no K_TO
        interval (``None``: the data sheet's nominal value) K_g is not resolved."""
        n = len(self.repetitions)
        if n < 2:
            return Estimate(
                self.kg, math.nan, math.nan, False, "one repetition gives no spread to judge it by"
            )
        q = float(scipy.stats.t.ppf(0.975, n - 1))
        rel = math.hypot(q * self.kg_se / self.kg, kto_rel_half_width or 0.0)
        rel += self.partner_bound
        e = judged(self.kg, self.kg * (1 - rel), self.kg * (1 + rel))
        if kto_rel_half_width is None:
            return Estimate(
                e.value,
                e.lo,
                e.hi,
                False,
                "K_TO is the data sheet's nominal value, not a measurement",
            )
        return e

    def tau_estimate(self) -> Estimate:
        """h/k with its 95 % interval (1/k over k's t interval), never resolved
        (``H_OVER_K_UNRESOLVED``): it serves only the x coth x correction, a few 0.01 %."""
        if self.tau_s is None or self.tau_se is None:
            return Estimate(
                math.nan, math.nan, math.inf, False, "the restraint is not resolved by the record"
            )
        k, k_se = 1.0 / self.tau_s, self.tau_se / self.tau_s**2
        ek = from_stderr(k, k_se, dof=self.restraint_dof)
        hi = 1.0 / ek.lo if ek.lo > 0 else math.inf
        # the fit's 1/k is h/k (1 + (c/h)_a (c/h)_b) (the partner's loop answers through the
        # float's viscous coupling): taken out with the data sheet's h/c, the bound spanning each
        # h/c's tolerance (left in, the X-Y float's Y read 2-3 % high and its bound missed the
        # truth on 3 of 18 drawn rigs)
        tol = VISCOUS_COUPLING_TOLERANCE
        cc = self.coupling_carried
        return Estimate(
            self.tau_s / (1.0 + cc),
            1.0 / ek.hi / (1.0 + (1.0 + tol) ** 2 * cc),
            hi / (1.0 + (1.0 - tol) ** 2 * cc),
            False,
            H_OVER_K_UNRESOLVED,
        )


@dataclass(frozen=True)
class ChannelRun(StepResult):
    """One channel's stopwatch step: the K_TO used (``kto`` urad/s/V, from ``kto_from``, its
    relative 95 % half-width ``kto_rel_ci95``), the pickoff change timed ``dVg`` (V), the ramps
    (direction, dt s, torquer step V), the restraint fits (``restraint_fit``: with the partner
    term ``fit``, without it ``slope_fit``), the partner factor per ramp (``partner_factors``;
    empty in older runs), the null's residual slope (V/s); and, for the report, the loop gain,
    the null, the pickoff's centre ``vg0`` (V), how long the loops were caged and the times
    (opened, nulled, end; rig s)."""

    #: the fits' figures far finer than their standard errors; 15 digits did not fit the event
    digits: ClassVar[int] = 7

    ch: str
    kto: float
    kto_from: str
    dVg: float
    ramps: tuple[tuple[int, float, float], ...]
    fit: dict[str, float]
    null_slope: float = 0.0
    slope_fit: dict[str, float] | None = None
    partner_factor: tuple[float, ...] = ()
    kto_rel_ci95: float | None = None
    gain: float | None = None
    vt_null: float | None = None
    vg0: float = 0.0
    caged_for_s: float | None = None
    t: tuple[float, float, float] | None = None


def channel_result(r: ChannelRun, h_over_c: Mapping[str, float] | None = None) -> ChannelResult:
    """Stopwatch readings (with the restraint correction x coth x) from a channel step's result;
    ``h_over_c`` the data sheet's viscous coupling per channel (for h/k's bound)."""
    kto = r.kto
    fit = r.fit
    k, k_se = fit["k"], fit["k_se"]
    resolved = k > 0 and k > 2 * k_se
    tau = 1.0 / k if resolved else None
    naive, corrected, restraint = [], [], []
    # the float partner's transient over each window (``partner_factors``; absent in older results)
    factors = r.partner_factor
    partner = list(factors) if factors and len(factors) == len(r.ramps) else [1.0] * len(r.ramps)
    for (_direction, dt, dvt), pf in zip(r.ramps, partner):
        kg = r.dVg / (dt * abs(dvt) * kto) * 1e3  # II C.1.a(6), V/urad -> mV/urad
        x = dt / (2 * tau) if tau else 0.0
        naive.append(kg)
        restraint.append(x / math.tanh(x) if x > 0 else 1.0)
        corrected.append(kg * restraint[-1] / pf)
    reps = [float(np.mean(corrected[i : i + 2])) for i in range(0, len(corrected) - 1, 2)]
    up = [c for c, (d, *_) in zip(corrected, r.ramps) if d > 0]
    down = [c for c, (d, *_) in zip(corrected, r.ramps) if d < 0]
    kg = float(np.mean(reps))
    spread = float(np.std(reps, ddof=1) / kg) if len(reps) > 1 else 0.0
    ls = r.slope_fit if r.slope_fit is not None else fit
    kg_ls = abs(ls["a"]) / kto * 1e3
    return ChannelResult(
        r.ch,
        kto,
        r.kto_from,
        corrected,
        naive,
        reps,
        float((np.mean(up) - np.mean(down)) / kg) if up and down else 0.0,
        kg,
        kg * spread / math.sqrt(len(reps)) if len(reps) > 1 else float("nan"),
        spread,
        kg_ls,
        ls["a_se"] / kto * 1e3,
        tau,
        (k_se / k**2) if resolved else None,
        float(np.mean(restraint) - 1.0),
        r.null_slope / (kg * 1e-3),
        int(fit.get("dof", 1)),
        float(np.mean([1.0 / pf - 1.0 for pf in partner])),
        (
            float(np.mean([PARTNER_MODEL_UNCERTAINTY[0] * abs(1.0 / pf - 1.0) for pf in partner]))
            + PARTNER_MODEL_UNCERTAINTY[1]
        )
        if factors
        else PARTNER_TRANSIENT_BOUND,
        1.0 / (h_over_c[r.ch] * h_over_c[FLOAT_PARTNER[r.ch]]) if h_over_c else 0.0,
    )
