"""Octave-band display of a spectrum, as the thesis plots them (App. A.8).

Klinger 1974, App. A.8 "Graphical Representation": on a log-log plot the equally spaced
estimates crowd together with increasing frequency, so "break up the spectrum into bands
each twice as large as the next lower band and display only the average of the points in
each band"; and because a spectral line "can be lost due to the averaging", "any points
greater than three times the average value are also plotted".

``octave_bands`` does exactly that for any real spectral function on a frequency grid (a
PSD, a coherence, a gain):

* DC (and any f <= 0, e.g. the negative half of a two-sided spectrum) is left out;
* band k covers ``[f1 2^k, f1 2^(k+1))`` with ``f1`` the first non-zero frequency, so on a
  uniform grid ``f_n = n df`` band k holds the bins ``n = 2^k .. 2^(k+1) - 1``: one bin,
  then 2, 4, 8, ... (the last band holds whatever is left up to the highest bin);
* each band is shown as the plain mean of its bins, at the mean of their frequencies (the
  thesis does not say where the average is drawn; the centroid of the averaged points is
  where an arithmetic average of a smooth spectrum belongs, about 1.5 f_lo here against
  the geometric centre's 1.41 f_lo);
* the bins greater than ``factor`` (3) times their band's mean are "kept" and plotted too.

The rule has a known side effect, inherent in App. A.8: where the spectrum falls steeply
across a band (faster than about f^-3.5, i.e. 35 dB/decade, as above a loop's bandwidth or
in an anti-alias filter's skirt), the band's lowest bins exceed three times its average
with no line there (for a slope f^-a the first bin stands (a-1)/(1-2^(1-a)) times above
the average: 2.7 for a = 3, 3.0 for a = 3.5, 3.4 for a = 4). A kept point is a candidate
line to look at, not a detection.

``band_average_dof`` gives the equivalent degrees of freedom of such a band mean, for its
chi-square confidence interval (App. A.4): averaging m adjacent bins multiplies a single
bin's EDOF by the number of effectively independent bins among them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal

__all__ = ["OctaveBands", "band_average_dof", "octave_bands"]

#: Relative tolerance on the band edges, so that a bin computed as n * df with rounding
#: (e.g. 3.9999999999999996 df for n = 4) lands in the band its index says.
EDGE_RTOL = 1e-9


@dataclass(frozen=True)
class OctaveBands:
    """Octave-band averages of a spectrum and the points kept above them (App. A.8).

    Per band (arrays of length ``n_bands``, lowest band first): ``f_lo`` .. ``f_hi`` its
    nominal edges (``f1 2^k`` .. ``f1 2^(k+1)``), ``f_center`` the mean frequency of its
    bins, ``average`` the mean of its finite values (nan if none), ``count`` its number of
    bins. Per kept point: ``kept_f``, ``kept_p`` and ``kept_band`` (its band's index); a
    point is kept when it is greater than ``factor`` times its band's average. Per input
    bin: ``band_index`` (-1 for DC and f <= 0, which are in no band).
    """

    f_lo: np.ndarray
    f_hi: np.ndarray
    f_center: np.ndarray
    average: np.ndarray
    count: np.ndarray
    kept_f: np.ndarray
    kept_p: np.ndarray
    kept_band: np.ndarray
    band_index: np.ndarray
    factor: float
    f1: float

    @property
    def n_bands(self) -> int:
        return len(self.average)


def octave_bands(f, p, *, factor: float = 3.0, f1: float | None = None) -> OctaveBands:
    """Average the spectrum ``p(f)`` over octave bands and keep the points above
    ``factor`` times their band's average (Klinger 1974, App. A.8).

    Parameters
    ----------
    f : array_like, 1-D
        Frequencies (Hz), in any order; bins with f <= 0 (DC) belong to no band.
    p : array_like, 1-D, real
        The spectral function at ``f`` (a PSD, a coherence, ...). Non-finite values count
        as points of their band but are left out of its average and never kept.
    factor : float
        A point is kept when ``p > factor * average`` of its band (the thesis's 3).
    f1 : float, optional
        Lower edge of the first band; default the lowest positive frequency in ``f``.
        Bins below it belong to no band.

    Returns
    -------
    OctaveBands
        Band ``k`` covers ``[f1 2^k, f1 2^(k+1))`` (edges compared with a relative
        tolerance of ``EDGE_RTOL``); bands run up to the one holding the highest bin, and
        none is empty on a uniform grid.
    """
    f = np.asarray(f, dtype=float)
    p = np.asarray(p, dtype=float)
    if f.ndim != 1 or p.shape != f.shape:
        raise ValueError(f"f and p must be 1-D of one length, got shapes {f.shape} and {p.shape}")
    if not factor > 0:
        raise ValueError(f"factor={factor} must be > 0")
    positive = f[f > 0]
    if f1 is None:
        if positive.size == 0:
            raise ValueError("the spectrum has no positive frequency: nothing to band")
        f1 = float(positive.min())
    if not f1 > 0:
        raise ValueError(f"f1={f1} must be > 0")
    fmax = float(positive.max()) if positive.size else f1
    n_bands = max(1, int(np.floor(np.log2(fmax / f1) + EDGE_RTOL)) + 1)
    lo = f1 * 2.0 ** np.arange(n_bands)
    hi = 2.0 * lo
    edges = np.append(lo, hi[-1]) * (1.0 - EDGE_RTOL)
    idx = np.searchsorted(edges, f, side="right") - 1
    idx[(f <= 0) | (idx < 0) | (idx >= n_bands)] = -1
    inb = idx >= 0
    finite = inb & np.isfinite(p)
    count = np.bincount(idx[inb], minlength=n_bands)
    n_fin = np.bincount(idx[finite], minlength=n_bands)
    p_sum = np.bincount(idx[finite], weights=p[finite], minlength=n_bands)
    f_sum = np.bincount(idx[inb], weights=f[inb], minlength=n_bands)
    with np.errstate(invalid="ignore", divide="ignore"):
        average = np.where(n_fin > 0, p_sum / n_fin, np.nan)
        f_center = np.where(count > 0, f_sum / count, np.nan)
    threshold = np.full(f.shape, np.inf)
    threshold[inb] = factor * average[idx[inb]]
    with np.errstate(invalid="ignore"):
        kept = finite & (p > threshold)
    return OctaveBands(
        f_lo=lo,
        f_hi=hi,
        f_center=f_center,
        average=average,
        count=count,
        kept_f=f[kept],
        kept_p=p[kept],
        kept_band=idx[kept],
        band_index=idx,
        factor=float(factor),
        f1=f1,
    )


def _bin_correlations(window, nperseg: int, nfft: int, max_lag: int) -> np.ndarray:
    """rho(d), d = 0 .. max_lag: the correlation of the periodogram values of bins d apart
    for white Gaussian data, |sum w^2 e^{-j 2 pi d m / nfft}|^2 / (sum w^2)^2 (the frequency
    dual of Welch's segment-overlap correlation in ``spectra.equivalent_dof``)."""
    w = (
        scipy.signal.get_window(window, nperseg)
        if isinstance(window, (str, tuple))
        else np.asarray(window, float)
    )
    W2 = np.fft.fft(w * w, n=nfft)
    lags = np.arange(max_lag + 1) % nfft
    return np.abs(W2[lags]) ** 2 / np.abs(W2[0]) ** 2


def band_average_dof(
    dof_bin: float, count, *, window="hann", nperseg: int, nfft: int | None = None
) -> np.ndarray:
    r"""Equivalent degrees of freedom of the mean of ``count`` adjacent bins (App. A.4).

    Each bin of a Welch estimate is about :math:`\chi^2_\nu/\nu` distributed with
    ``dof_bin`` = :math:`\nu` (``spectra.equivalent_dof``). Adjacent bins of a windowed
    transform are correlated (Hann: :math:`\rho(1) = 4/9`, :math:`\rho(2) = 1/36`), so the
    mean of m of them has

    .. math:: \nu_m = \nu \frac{m^2}{m + 2\sum_{d=1}^{m-1} (m - d)\,\rho(d)},

    about :math:`\nu m / 1.94` for large m with Hann, and :math:`\nu m` for independent bins
    (boxcar, no zero padding). Like Welch's EDOF this assumes Gaussian data and a spectrum
    smooth across the averaged bins; a band holding a line is not chi-square. ``count`` may
    be an array (one per band); returns an array of its shape.
    """
    m = np.atleast_1d(np.asarray(count, dtype=int))
    nfft = nperseg if nfft is None else int(nfft)
    top = int(m.max()) if m.size else 1
    if top > nfft // 2 + 1:
        raise ValueError(
            f"a band of {top} bins does not fit in the {nfft // 2 + 1} bins of a one-sided "
            f"spectrum of nfft={nfft}"
        )
    rho = _bin_correlations(window, nperseg, nfft, max(top - 1, 0))
    out = np.empty(m.shape, dtype=float)
    for i, mi in enumerate(m.flat):
        if mi < 1:
            out.flat[i] = np.nan
            continue
        d = np.arange(1, mi)
        denom = mi + 2.0 * float(np.sum((mi - d) * rho[1:mi]))
        out.flat[i] = dof_bin * mi * mi / denom
    return out.reshape(np.shape(count))
