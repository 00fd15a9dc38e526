"""The pickoff lines as the measured unit has them: frequencies found in the data.

DESIGN.md section 3 gives the gyro pickoff's discrete lines only roughly ("a 71 Hz pair 0.8 Hz
apart, 102 Hz, 187 Hz"), and another gyro's sit a fraction of a hertz away: with the data
sheet's frequencies a line lands a few bins off in the model and reads as a departure of
ten or twenty dB. They are unit-to-unit variation, not physics the model lacks, so each line's
frequency is read off the measured gyro channel (the strongest first, each within
``SEARCH_HZ`` of its data-sheet value and clear of the lines already placed), and its power
is a nuisance scale fitted with the noise levels (``model.line_part``).

The frequency is the Hann periodogram's peak bin refined by a parabola through the logarithm
of the peak and its two neighbours (Gaussian interpolation: [Gasior and Gonzalez 2004] give
its bias for the Hann window as under 2 % of a bin).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import scipy.optimize

from procedures.analysis.gap.grid import Grid
from simhw.params import SimConfig

log = logging.getLogger(__name__)

#: how far from its data-sheet frequency a line is looked for (unit-to-unit spread +-0.5 Hz)
SEARCH_HZ = 0.75
#: two lines are not placed closer than this (the 71 Hz pair is ~0.8 Hz apart)
MIN_SEPARATION_HZ = 0.35
#: a peak must stand this far above the median of its search window to be taken as the line
MIN_PROMINENCE = 10.0


def found_pickoff_lines(cfg: SimConfig, axis: str, channels: tuple[str, ...], p_bins: np.ndarray,
                        grid: Grid) -> SimConfig:
    """A copy of ``cfg`` with the axis gyro's pickoff lines at the frequencies found in the
    measured ``gyro_<axis>`` channel's periodogram ``p_bins`` (bins of ``grid``); a line the
    data do not show (no gyro channel, beyond the analysed band, no prominent peak) keeps its
    data-sheet frequency."""
    name = f"gyro_{axis.lower()}"
    lines = [list(map(float, ln)) for ln in cfg.gyro[axis].pickoff_lines]
    if name not in channels or not lines:
        return cfg
    f, p, df = grid.f, p_bins[channels.index(name)], grid.df
    placed: list[float] = []
    for k in sorted(range(len(lines)), key=lambda i: -lines[i][1]):
        f0 = lines[k][0]
        sel = np.abs(f - f0) <= SEARCH_HZ
        for fp in placed:
            sel &= np.abs(f - fp) > MIN_SEPARATION_HZ
        idx = np.flatnonzero(sel)
        if len(idx) < 3:
            continue
        j = idx[np.argmax(p[idx])]
        if not (0 < j < len(p) - 1) or p[j] < MIN_PROMINENCE * np.median(p[idx]):
            continue
        y0, y1, y2 = np.log(p[j - 1:j + 2])
        curve = y0 - 2 * y1 + y2
        delta = float(np.clip(0.5 * (y0 - y2) / curve, -0.5, 0.5)) if curve < 0 else 0.0
        lines[k][0] = float(f[j] + delta * df)
        placed.append(lines[k][0])
    out = cfg.copy()
    out.gyro[axis].pickoff_lines = lines
    moved = [f"{a[0]:.2f} -> {b[0]:.3f} Hz" for a, b in zip(cfg.gyro[axis].pickoff_lines, lines) if a[0] != b[0]]
    if moved:
        log.info("pickoff lines of gyro %s found in the data: %s", axis, ", ".join(moved))
    return out


#: A line's record periodogram peak over its mean across the search span, as a share of a pure
#: sinusoid's (2/3 span T for the Hann window, by Parseval: 36 at 300 s and +-1.5 Welch bins);
#: the largest of span T independent noise bins exceeds 0.3 of that with probability
#: span T exp(-0.2 span T): 54 e^-10.8 = 0.1 % in that case.
LINE_NARROWNESS = 0.3


@dataclass(frozen=True)
class MeasuredLine:
    """An excess measured as a sinusoid on the whole record (``refine_line``)."""

    freq_hz: float
    sigma_hz: float
    amplitude: float      # in the record's units (biased up by the noise in its bin)
    narrowness: float     # periodogram peak over its mean across the search span, as a share of a sinusoid's

    @property
    def is_line(self) -> bool:
        """Narrow as the window makes a sinusoid, not a resonance's or a noise band's width."""
        return self.narrowness >= LINE_NARROWNESS


def refine_line(x: np.ndarray, rate_hz: float, f0: float, search_hz: float, noise_psd: float) -> MeasuredLine:
    """A sinusoid's frequency near ``f0`` measured on the whole record.

    A pickup line's frequency is exact to the record's resolution and far beyond: the
    maximum of the record's Hann-windowed periodogram is the maximum-likelihood estimate of a
    single sinusoid in locally white noise [Rife and Boorstyn 1974]. The record is first
    shifted by ``f0`` and summed in blocks (a boxcar low-pass: ``search_hz`` is well inside its
    first null), then the periodogram of the short sequence is maximized by a bounded scalar
    search within ``f0 +- search_hz``. Its 1-sigma is the windowed estimator's: with the
    window w at times tau from the record's centre and white noise of variance
    sigma^2 = S fs / 2 (``noise_psd`` S, one-sided), var(omega) = 2 sigma^2 sum w^2 tau^2 /
    (A^2 (sum w tau^2)^2) (linearized about the peak; for w = 1 it is the Cramer-Rao bound
    24 sigma^2 / (A^2 N^3) of [Rife and Boorstyn 1974, eq. 20]); never below 1 % of 1/T.

    Shape: a line's width is the window's (the record periodogram's peak stands far above its
    mean across the search span); a resonance or a noise excess is as wide as its damping or
    its band (``MeasuredLine.is_line``)."""
    n = len(x)
    T = n / rate_hz
    t = np.arange(n) / rate_hz
    w = np.hanning(n)
    z = (x - x.mean()) * w * np.exp(-2j * np.pi * f0 * t)
    block = max(1, int(rate_hz / (20.0 * max(search_hz, 1.0 / T))))
    m = n // block
    zb = z[: m * block].reshape(m, block).sum(axis=1)
    tb = (np.arange(m) * block + 0.5 * (block - 1)) / rate_hz

    def power(df: float) -> float:
        return -float(np.abs(np.sum(zb * np.exp(-2j * np.pi * df * tb))) ** 2)

    grid = np.linspace(-search_hz, search_hz, max(9, int(8 * search_hz * T) + 1))
    powers = np.array([power(g) for g in grid])
    k = int(np.argmin(powers))
    step = grid[1] - grid[0]
    res = scipy.optimize.minimize_scalar(power, bounds=(grid[k] - step, grid[k] + step), method="bounded",
                                         options={"xatol": 1e-4 / T})
    df = float(res.x)
    amplitude = 2.0 * math.sqrt(-power(df)) / float(np.sum(w))
    tau = t - 0.5 * T
    var_w = (2.0 * max(noise_psd, 0.0) * rate_hz / 2 * float(np.sum(w * w * tau * tau))
             / max(amplitude**2 * float(np.sum(w * tau * tau)) ** 2, 1e-300))
    sigma = math.sqrt(var_w) / (2 * math.pi)
    span = grid[-1] - grid[0]
    narrowness = float(powers[k] / np.mean(powers)) / (2.0 / 3.0 * span * T) if np.mean(powers) < 0 else 0.0
    return MeasuredLine(f0 + df, max(sigma, 0.01 / T), amplitude, narrowness)
