"""Prewhitening before spectral estimation, as the thesis did it (App. A.3).

Power concentrated at DC, in a drift or at one frequency leaks through the window's side
lobes and buries the spectrum near it, so it is removed first: a straight line and/or a sine
wave is fitted by unweighted least squares and subtracted. Bad points are then found in the
residual: every point beyond 4 sigma (sigma the residual's sample standard deviation) is
listed and set to the residual mean, and if any was found the whole procedure is repeated
without them, until none remain.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import scipy.optimize

log = logging.getLogger(__name__)

#: Points beyond this many residual standard deviations are bad data (App. A.3).
OUTLIER_SIGMA = 4.0


@dataclass
class Prewhitened:
    """The residual and what was taken out of the data."""

    residual: np.ndarray
    line: tuple[float, float] | None  # (offset, slope per second) at t = 0
    sine: (
        tuple[float, float, float] | None
    )  # (frequency Hz, amplitude, phase rad): a sin(2 pi f t + phase)
    outliers: list[tuple[int, float]] = field(default_factory=list)  # (index, original value)
    passes: int = 1


def _design(t: np.ndarray, line: bool, freq_hz: float | None) -> np.ndarray:
    cols = []
    if line:
        cols += [np.ones_like(t), t]
    if freq_hz is not None:
        w = 2 * np.pi * freq_hz
        cols += [np.sin(w * t), np.cos(w * t)]
    return np.column_stack(cols) if cols else np.zeros((len(t), 0))


def _fit(x: np.ndarray, t: np.ndarray, ok: np.ndarray, line: bool, freq_hz: float | None):
    a = _design(t, line, freq_hz)
    if a.shape[1] == 0:
        return np.zeros(0), np.zeros_like(x)
    coef, *_ = np.linalg.lstsq(a[ok], x[ok], rcond=None)
    return coef, a @ coef


def _best_frequency(x: np.ndarray, t: np.ndarray, ok: np.ndarray, fs: float, line: bool) -> float:
    """Periodogram peak of the (line-removed) data, refined by least squares on the frequency."""
    _, base = _fit(x, t, ok, line, None)
    r = np.where(ok, x - base, 0.0)
    spec = np.abs(np.fft.rfft(r)) ** 2
    spec[0] = 0.0
    k = int(np.argmax(spec))
    df = fs / len(x)

    def cost(f: float) -> float:
        _, model = _fit(x, t, ok, line, f)
        return float(np.sum((x - model)[ok] ** 2))

    res = scipy.optimize.minimize_scalar(
        cost,
        bounds=(max(df * (k - 1), df * 0.1), df * (k + 1)),
        method="bounded",
        options={"xatol": df * 1e-4},
    )
    return float(res.x)


def prewhiten(
    x: np.ndarray,
    fs: float,
    *,
    line: bool = True,
    sine_hz: float | Literal["auto"] | None = None,
    max_passes: int = 20,
) -> Prewhitened:
    """Remove a least-squares line and/or sine and the 4-sigma outliers (App. A.3).

    ``sine_hz``: None (no sine), a frequency in Hz, or ``"auto"`` (the periodogram's largest
    line, refined by least squares). Returns the residual with every bad point set to the
    residual mean; the outliers are listed with their original values.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 1 or len(x) < 4:
        raise ValueError(f"prewhiten needs a 1-D record of at least 4 samples, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        bad = int(np.count_nonzero(~np.isfinite(x)))
        raise ValueError(
            f"prewhiten: {bad} samples are NaN or infinite (gaps?); cut the record at the gaps first"
        )
    if not fs > 0:
        raise ValueError(f"sample rate {fs!r} Hz must be > 0")
    if isinstance(sine_hz, str) and sine_hz != "auto":
        raise ValueError(f"sine_hz={sine_hz!r}: give None, a frequency in Hz or 'auto'")
    t = np.arange(len(x)) / fs
    ok = np.ones(len(x), bool)
    outliers: list[tuple[int, float]] = []
    passes = 0
    while True:
        passes += 1
        freq = _best_frequency(x, t, ok, fs, line) if isinstance(sine_hz, str) else sine_hz
        coef, model = _fit(x, t, ok, line, freq)
        r = x - model
        mean, sigma = float(np.mean(r[ok])), float(np.std(r[ok]))
        bad = ok & (np.abs(r - mean) > OUTLIER_SIGMA * sigma)
        if not bad.any():
            break
        for i in np.flatnonzero(bad):
            outliers.append((int(i), float(x[i])))
            log.info("prewhiten: sample %d = %g is beyond %g sigma", i, x[i], OUTLIER_SIGMA)
        ok &= ~bad
        if passes == max_passes:
            log.warning("prewhiten: outliers still found after %d passes", max_passes)
            break
    residual = np.where(ok, r, mean)
    line_fit = (float(coef[0]), float(coef[1])) if line else None
    sine_fit = None
    if freq is not None:
        s, c = coef[-2], coef[-1]
        sine_fit = (float(freq), float(np.hypot(s, c)), float(np.arctan2(c, s)))
    outliers.sort()
    return Prewhitened(residual, line_fit, sine_fit, outliers, passes)
