"""Where the measurement departs from the model beyond statistical confidence.

Band by band, ``nu P / S`` is chi-square with ``nu`` degrees of freedom if the model is right
(App. A.4). A band departs when its two-sided p-value is below ``alpha`` divided by the number
of bands tested (Bonferroni: the chance of any false departure in a file stays below
``alpha``) *and* the measured level differs from the model by more than ``tol_db``: the model's
own parameters are known to a few per cent, and with thousands of degrees of freedom a
1 % discrepancy would otherwise count. Steps found in the time domain (``steps.py``) are the
other kind of departure.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.special
import scipy.stats

from procedures.analysis.gap.grid import Grid


@dataclass(frozen=True)
class Band:
    """A run of adjacent departing bands of one channel."""

    channel: str
    f_lo_hz: float
    f_hi_hz: float
    peak_hz: float
    deviation_db: float  # the largest |measured / model| in the run, signed


@dataclass
class Evidence:
    """What the comparison found, as the effects' ``guess`` hooks read it."""

    duration_s: float
    peaks_hz: list[float] = field(default_factory=list)  # where the measurement exceeds the model
    steps_urad: list[float] = field(default_factory=list)
    dips_hz: list[float] = field(default_factory=list)  # where it falls short (a notch)
    #: the excesses as narrow as a sinusoid, measured on the record: (freq_hz, 1-sigma Hz)
    lines: list[tuple[float, float]] = field(default_factory=list)


def departures(
    P: np.ndarray, S: np.ndarray, dof: np.ndarray, *, alpha: float = 0.01, tol_db: float = 0.5
) -> np.ndarray:
    """Boolean (n_channels, n_bands): bands beyond confidence and tolerance."""
    dof = np.broadcast_to(dof, P.shape)
    x = dof * P / S
    p = 2.0 * np.minimum(scipy.stats.chi2.cdf(x, dof), scipy.stats.chi2.sf(x, dof))
    dev = 10.0 * np.log10(P / S)
    return (p < alpha / P.size) & (np.abs(dev) > tol_db)


def bands(
    flags: np.ndarray,
    P: np.ndarray,
    S: np.ndarray,
    grid: Grid,
    channels: tuple[str, ...],
    bin_ratio: np.ndarray | None = None,
) -> list[Band]:
    """Runs of departing bands per channel, largest departure first. ``bin_ratio`` (measured over
    model, per analysed bin) places each run's peak at bin resolution."""
    out = []
    dev = 10.0 * np.log10(P / S)
    for i, ch in enumerate(channels):
        idx = np.flatnonzero(flags[i])
        if len(idx) == 0:
            continue
        runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
        for run in runs:
            k = run[np.argmax(np.abs(dev[i, run]))]
            peak = float(grid.band_center_hz[k])
            if bin_ratio is not None and dev[i, k] > 0:
                in_run = np.isin(grid.band_of_bin, run)
                pos = np.flatnonzero(in_run)
                peak = float(grid.f[pos[np.argmax(bin_ratio[i, pos])]])
            out.append(
                Band(
                    ch,
                    float(grid.band_lo_hz[run[0]]),
                    float(grid.band_hi_hz[run[-1]]),
                    peak,
                    float(dev[i, k]),
                )
            )
    return sorted(out, key=lambda b: -abs(b.deviation_db))


def gap_db(P: np.ndarray, S: np.ndarray, cells: np.ndarray, dof: np.ndarray | None = None) -> float:
    """The gap: rms over the located (channel, band) cells of 10 log10(measured / model), dB.
    Zero when nothing was located.

    With ``dof`` (each cell's equivalent degrees of freedom) the estimate's own scatter is taken
    out: a band estimate is S chi^2_nu / nu, so 10 log10(P/S) has mean c (psi(nu/2) - ln(nu/2))
    and variance c^2 psi'(nu/2) under a right model (c = 10 / ln 10); with the mean removed from
    each d, the gap is the rms left over, sqrt(max(mean(d^2) - mean(variance), 0)). A model that
    is right has gap 0 however few degrees of freedom the located bands have, so "the gap halved"
    compares the models and not the record's noise floor.
    """
    if not cells.any():
        return 0.0
    d = 10.0 * np.log10(P[cells] / S[cells])
    if dof is None:
        return float(np.sqrt(np.mean(d * d)))
    half = 0.5 * np.broadcast_to(dof, P.shape)[cells]
    c = 10.0 / np.log(10.0)
    d = d - c * (scipy.special.digamma(half) - np.log(half))  # the log estimate's bias
    ms = float(
        np.mean(d * d) - np.mean(c * c * scipy.special.polygamma(1, half))
    )  # less its variance
    return float(np.sqrt(max(ms, 0.0)))
