"""The stopwatch numerics: K_g = dV_g / (dt dV_T K_TO) (thesis II C.1.a(6)) from a channel's
open-loop record, with the elastic restraint's correction. Arrays and the channel step's result
dict in, plain values out; no rig. The procedure (the steps, the null, the ramps) is
``procedures.calibrations.stopwatch``, whose docstring has the method; the report's table and
plot are ``procedures.reports.stopwatch``.

* ``crossing_interval``: one stopwatch reading, the time between the smoothed pickoff's
  crossings of the two levels of a ramp;
* ``restraint_fit``: tau = h/k from a least-squares fit of the whole open-loop record (step 4
  of the method);
* ``channel_result``: the readings corrected by x coth x, x = dt / (2 tau), their mean per
  down-up pair and the spread.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


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


def crossing_interval(t: np.ndarray, vg: np.ndarray, lo: float, hi: float, direction: int, smooth_s: float,
                      rate_hz: float) -> float:
    """Time between the smoothed pickoff's crossings of the two levels (linear interpolation).
    Raises ``NoCrossing`` if it does not cross one of them."""
    s = smooth(vg, int(round(smooth_s * rate_hz)))
    first, second = (lo, hi) if direction > 0 else (hi, lo)

    def cross(level: float) -> float:
        beyond = (s - level) * direction >= 0
        idx = np.flatnonzero(beyond[1:] & ~beyond[:-1])
        if len(idx) == 0:
            raise NoCrossing(f"stopwatch: the pickoff never crossed {level:+.4f} V during a ramp")
        i = idx[0]
        return float(t[i] + (level - s[i]) / (s[i + 1] - s[i]) * (t[i + 1] - t[i]))

    return cross(second) - cross(first)


def restraint_fit(t: np.ndarray, vg: np.ndarray, vt: np.ndarray, *, vt_null: float, vg0: float,
                  dt_s: float) -> dict:
    """Least squares of V_g(t) - V_g(t0) = a int(V_T - V_T0) + c (t - t0) - k int(V_g - V_g0) (+ offset),
    on ``dt_s`` means (``procedures.calibrations.stopwatch``'s docstring, step 4)."""
    step = t[1] - t[0]
    n = max(1, int(round(dt_s / step)))
    m = len(t) // n * n
    tm = t[:m].reshape(-1, n).mean(axis=1)
    g = vg[:m].reshape(-1, n)
    gm, vtm = np.nanmean(g, axis=1), np.nanmean(vt[:m].reshape(-1, n), axis=1)
    it = np.concatenate([[0.0], np.cumsum((vtm[1:] + vtm[:-1]) / 2 - vt_null) * np.diff(tm)])
    ig = np.concatenate([[0.0], np.cumsum((gm[1:] + gm[:-1]) / 2 - vg0) * np.diff(tm)])
    design = np.column_stack([np.ones_like(tm), it, tm - tm[0], -ig])
    ok = np.isfinite(gm) & np.isfinite(it) & np.isfinite(ig)
    coef, *_ = np.linalg.lstsq(design[ok], gm[ok], rcond=None)
    resid = gm[ok] - design[ok] @ coef
    cov = np.linalg.inv(design[ok].T @ design[ok]) * (resid @ resid) / max(1, ok.sum() - 4)
    se = np.sqrt(np.diag(cov))
    return {"a": float(coef[1]), "a_se": float(se[1]), "c": float(coef[2]), "k": float(coef[3]),
            "k_se": float(se[3]), "rms": float(np.sqrt(np.mean(resid ** 2)))}


@dataclass
class ChannelResult:
    channel: str
    kto: float
    kto_from: str
    readings: list[float]          # corrected stopwatch K_g per ramp, mV/urad
    naive: list[float]             # uncorrected
    repetitions: list[float]       # mean of each down-up pair
    asymmetry: float               # (up - down) / mean: a rate offset during the ramps
    kg: float
    kg_se: float
    spread: float
    kg_ls: float
    kg_ls_se: float
    tau_s: float | None
    tau_se: float | None
    correction: float              # mean (corrected / naive - 1)
    null_rate_urad_per_s: float


def channel_result(r: dict) -> ChannelResult:
    """Stopwatch readings (with the restraint correction x coth x) from a channel step's result."""
    kto = r["kto"]
    fit = r["fit"]
    k, k_se = fit["k"], fit["k_se"]
    resolved = k > 0 and k > 2 * k_se
    tau = 1.0 / k if resolved else None
    naive, corrected = [], []
    for _direction, dt, dvt in r["ramps"]:
        kg = r["dVg"] / (dt * abs(dvt) * kto) * 1e3                         # II C.1.a(6), V/urad -> mV/urad
        x = dt / (2 * tau) if tau else 0.0
        naive.append(kg)
        corrected.append(kg * (x / math.tanh(x) if x > 0 else 1.0))
    reps = [float(np.mean(corrected[i:i + 2])) for i in range(0, len(corrected) - 1, 2)]
    up = [c for c, (d, *_) in zip(corrected, r["ramps"]) if d > 0]
    down = [c for c, (d, *_) in zip(corrected, r["ramps"]) if d < 0]
    kg = float(np.mean(reps))
    spread = float(np.std(reps, ddof=1) / kg) if len(reps) > 1 else 0.0
    kg_ls = abs(fit["a"]) / kto * 1e3
    return ChannelResult(r["ch"], kto, r["kto_from"], corrected, naive, reps,
                         float((np.mean(up) - np.mean(down)) / kg) if up and down else 0.0, kg,
                         kg * spread / math.sqrt(len(reps)) if len(reps) > 1 else float("nan"), spread,
                         kg_ls, fit["a_se"] / kto * 1e3, tau, (k_se / k ** 2) if resolved else None,
                         float(np.mean(np.array(corrected) / np.array(naive)) - 1.0),
                         r["null_slope"] / (kg * 1e-3))
