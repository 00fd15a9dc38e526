"""The analysis grid of the model-gap workflow: Welch bins grouped into fractional-octave bands.

Measured and model spectra are compared band by band. A band is the mean of the Welch bins
(Hann, 50 % overlap, a line removed per segment) whose centres fall in one 1/24-octave
interval; low bands hold one bin, high bands hundreds. Each band's estimate is taken as
``S chi^2_nu / nu`` (App. A.4) with ``nu`` its equivalent degrees of freedom: the Welch EDOF
of one bin (``daq.spectral.equivalent_dof``) times the bins in the band, divided by the
variance inflation of summing adjacent, correlated bins (for Hann the periodograms of
neighbouring bins correlate by 4/9, two apart by 1/36).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.signal
import scipy.sparse

from daq.spectral import equivalent_dof, n_segments, psd, welch_csd_matrix

#: Bins per band below which a band's bins are all evaluated by the model; above, a subset.
MODEL_POINTS_PER_BAND = 8
#: Fewest Welch segments for the lowest band's estimate to be worth comparing.
MIN_SEGMENTS = 8


class GapInputError(ValueError):
    """The file cannot be analysed as it is: the message names the problem and the limit."""


@dataclass(frozen=True)
class Grid:
    """Welch parameters and the bands of one analysis."""

    rate_hz: float
    nperseg: int
    noverlap: int
    segments: int
    bins: np.ndarray  # Welch bin indices analysed
    band_of_bin: np.ndarray  # band index of each analysed bin
    band_lo_hz: np.ndarray
    band_hi_hz: np.ndarray
    dof: np.ndarray  # equivalent degrees of freedom of each band's estimate
    eval_bins: np.ndarray  # positions (into ``bins``) where the model is evaluated
    eval_band: np.ndarray  # band of each evaluation point

    @property
    def df(self) -> float:
        return self.rate_hz / self.nperseg

    @property
    def f(self) -> np.ndarray:
        return self.bins * self.df

    @property
    def n_bands(self) -> int:
        return len(self.band_lo_hz)

    @property
    def band_center_hz(self) -> np.ndarray:
        return np.sqrt(self.band_lo_hz * self.band_hi_hz)

    def band_mean(self, per_bin: np.ndarray) -> np.ndarray:
        """Mean over each band's bins of ``per_bin`` (..., n_bins) -> (..., n_bands)."""
        return _group_mean(per_bin, self._bin_averages)

    def eval_mean(self, per_point: np.ndarray) -> np.ndarray:
        """Mean over each band's evaluation points (..., n_points) -> (..., n_bands)."""
        return _group_mean(per_point, self._eval_averages)

    # a model evaluation averages a few dozen arrays: one sparse product each, its matrix made once
    @cached_property
    def _bin_averages(self) -> scipy.sparse.csr_matrix:
        return _averaging(self.band_of_bin, self.n_bands)

    @cached_property
    def _eval_averages(self) -> scipy.sparse.csr_matrix:
        return _averaging(self.eval_band, self.n_bands)


def _averaging(group: np.ndarray, n: int) -> scipy.sparse.csr_matrix:
    """(n, len(group)): row b averages the points of group b."""
    counts = np.bincount(group, minlength=n).astype(float)
    return scipy.sparse.csr_matrix(
        (1.0 / counts[group], (group, np.arange(len(group)))), shape=(n, len(group))
    )


def _group_mean(values: np.ndarray, averages: scipy.sparse.csr_matrix) -> np.ndarray:
    flat = values.reshape(-1, values.shape[-1])
    out = np.asarray(averages @ flat.T).T
    return out.reshape(values.shape[:-1] + (averages.shape[0],))


def _bin_correlation(window: np.ndarray, max_lag: int = 4) -> np.ndarray:
    """Correlation of the periodograms of bins j apart: |sum w^2 e^(-j 2 pi j m / N)|^2 / (sum w^2)^2."""
    w2 = window**2
    spec = np.fft.rfft(w2)[: max_lag + 1]
    return np.abs(spec) ** 2 / float(w2.sum()) ** 2


def make_grid(
    rate_hz: float,
    n_samples: int,
    *,
    df_hz: float = 0.0625,
    f_lo_hz: float = 0.25,
    f_hi_fraction: float = 0.3,
    bands_per_octave: int = 24,
) -> Grid:
    """Bins from ``f_lo_hz`` (at least the 4th bin, clear of the detrend's leakage) to
    ``f_hi_fraction`` of the rate, in 1/``bands_per_octave``-octave bands."""
    if not (rate_hz > 0 and math.isfinite(rate_hz)):
        raise GapInputError(f"sample rate {rate_hz!r} Hz must be a positive number")
    nperseg = 1 << max(8, math.ceil(math.log2(rate_hz / df_hz)))
    noverlap = nperseg // 2
    need = nperseg + (MIN_SEGMENTS - 1) * (nperseg - noverlap)
    if n_samples < need:
        raise GapInputError(
            f"record too short: {n_samples / rate_hz:.1f} s; the lowest band ({f_lo_hz:g} Hz, "
            f"{rate_hz / nperseg:.3f} Hz resolution) needs {MIN_SEGMENTS} segments of {nperseg / rate_hz:.1f} s, "
            f"at least {need / rate_hz:.1f} s"
        )
    K = n_segments(n_samples, nperseg, noverlap)
    df = rate_hz / nperseg
    k0 = max(4, math.ceil(f_lo_hz / df))
    k1 = int(f_hi_fraction * rate_hz / df)
    bins = np.arange(k0, k1 + 1)
    f = bins * df
    raw = np.floor(bands_per_octave * np.log2(f / (k0 * df)) + 1e-9).astype(int)
    _, band = np.unique(raw, return_inverse=True)
    n_bands = band.max() + 1
    lo = np.array([f[band == b].min() - df / 2 for b in range(n_bands)])
    hi = np.array([f[band == b].max() + df / 2 for b in range(n_bands)])
    win = scipy.signal.get_window("hann", nperseg)
    nu_bin = equivalent_dof(win, nperseg, noverlap, K)
    rho = _bin_correlation(win)
    counts = np.bincount(band)
    inflation = np.array(
        [1 + 2 * sum((1 - j / n) * rho[j] for j in range(1, min(n, len(rho)))) for n in counts]
    )
    dof = nu_bin * counts / inflation
    eval_pos: list[int] = []
    for b in range(n_bands):
        idx = np.flatnonzero(band == b)
        if len(idx) > MODEL_POINTS_PER_BAND:
            idx = idx[np.round(np.linspace(0, len(idx) - 1, MODEL_POINTS_PER_BAND)).astype(int)]
        eval_pos.extend(idx.tolist())
    eval_bins = np.array(eval_pos)
    return Grid(
        float(rate_hz), nperseg, noverlap, K, bins, band, lo, hi, dof, eval_bins, band[eval_bins]
    )


def bin_spectra(x: np.ndarray, grid: Grid) -> tuple[np.ndarray, np.ndarray]:
    """The analysed Welch bins: (f, p[n_channels, n_bins]), one-sided density."""
    f, p = psd(
        np.atleast_2d(x),
        grid.rate_hz,
        nperseg=grid.nperseg,
        noverlap=grid.noverlap,
        window="hann",
        detrend="linear",
    )
    return f[grid.bins], p[..., grid.bins]


def band_spectra(x: np.ndarray, grid: Grid) -> np.ndarray:
    """Band-averaged one-sided Welch PSD of each row of ``x`` (n_channels, n) -> (n_channels, n_bands)."""
    return grid.band_mean(bin_spectra(x, grid)[1])


def channel_weights(x: np.ndarray, grid: Grid) -> np.ndarray:
    """Each (channel, band)'s share of the evidence, (n_channels, n_bands): 1 / sum_d gamma^2_cd
    over the channels d (itself included), gamma^2 the band's magnitude-squared coherence
    (eq. 4.44) from the record's cross-spectral matrix.

    The channels are one measurement, not independent evidence (DESIGN.md section 8): the two
    autocollimator channels see one angle and one noise, and the power amplifier's input is the
    compensation network's image of the control channel, so in Mode 3 three of the four
    channels carry one spectrum (coherence near 1) and the gyro sees the platform through a
    noise of its own. Summing their Whittle terms as independent counts that spectrum three
    times, and a noise level the model misses by a little outweighs the plant physics the
    gyro tells apart. Weighting each channel's term by the inverse of its coherent
    multiplicity is the composite likelihood of the cross-spectral matrix's diagonal [Lindsay
    1988; Varin, Reid and Firth 2011]: coherent channels count once together, an incoherent
    channel counts in full, and the weights, fixed by the record, are the same for every model
    compared."""
    x = np.atleast_2d(x)
    if x.shape[0] == 1:
        return np.ones((1, grid.n_bands))
    _, S = welch_csd_matrix(
        x,
        grid.rate_hz,
        window="hann",
        nperseg=grid.nperseg,
        noverlap=grid.noverlap,
        detrend="linear",
    )
    S = S[grid.bins]
    n = x.shape[0]
    band = np.zeros((grid.n_bands, n, n), complex)
    np.add.at(band, grid.band_of_bin, S)
    d = np.maximum(np.real(np.einsum("bii->bi", band)), 1e-300)
    gamma2 = np.abs(band) ** 2 / (d[:, :, None] * d[:, None, :])
    return (1.0 / np.clip(gamma2, 0.0, 1.0).sum(axis=2)).T
