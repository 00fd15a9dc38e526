"""A sinusoid measured on a whole record: its frequency, amplitude and whether it is narrow as
a line (``refine_line``). Pure numerics, no model: the model-gap workflow measures pickup lines
with it (``procedures.analysis.gap.pickoff_lines``), the open-loop baseline the pickoff's lines
(``procedures.analysis.baseline``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.optimize

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
    amplitude: float  # in the record's units (biased up by the noise in its bin)
    narrowness: (
        float  # periodogram peak over its mean across the search span, as a share of a sinusoid's
    )

    @property
    def is_line(self) -> bool:
        """Narrow as the window makes a sinusoid, not a resonance's or a noise band's width."""
        return self.narrowness >= LINE_NARROWNESS


def refine_line(
    x: np.ndarray, rate_hz: float, f0: float, search_hz: float, noise_psd: float
) -> MeasuredLine:
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
    res = scipy.optimize.minimize_scalar(
        power,
        bounds=(grid[k] - step, grid[k] + step),
        method="bounded",
        options={"xatol": 1e-4 / T},
    )
    df = float(res.x)
    amplitude = 2.0 * math.sqrt(-power(df)) / float(np.sum(w))
    tau = t - 0.5 * T
    var_w = (
        2.0
        * max(noise_psd, 0.0)
        * rate_hz
        / 2
        * float(np.sum(w * w * tau * tau))
        / max(amplitude**2 * float(np.sum(w * tau * tau)) ** 2, 1e-300)
    )
    sigma = math.sqrt(var_w) / (2 * math.pi)
    span = grid[-1] - grid[0]
    narrowness = (
        float(powers[k] / np.mean(powers)) / (2.0 / 3.0 * span * T) if np.mean(powers) < 0 else 0.0
    )
    return MeasuredLine(f0 + df, max(sigma, 0.01 / T), amplitude, narrowness)
