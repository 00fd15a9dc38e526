"""Spectral estimates used across the project (thesis Ch. IV, App. A).

Welch averaging of windowed, detrended segments (App. A.2, A.4; Welch 1967), in the
conventions of ``scipy.signal`` so that every number here can be checked against it:

* densities are one-sided by default, so the power in a band is the plain integral of the
  PSD over it (the thesis's plots are two-sided: its areas are doubled, Ch. V B.2);
* ``S[f, i, j]`` is the cross-spectrum of channel ``i`` (first) and channel ``j`` (second),
  ``E[conj(X_i) X_j]`` as in eq. 4.41, so ``S_xy = H S_xx`` for ``y = h * x`` (eq. 4.36) and
  the phase of ``S_xy`` is the phase of ``H`` (eq. 4.38).

The toolkit:

``welch_csd_matrix``  the full N x N cross-spectral matrix from one pass of FFTs
``psd``               Welch PSD of one channel (or of each row of an array)
``coherence``         |S_ij|^2 / (S_ii S_jj) for the whole matrix (eq. 4.44, 4.49)
``coherence_pair``    the same for two signals, as ``scipy.signal.coherence``
``transfer_h1``       H1 = S_xy / S_xx (eq. 4.36-4.38), with ``gain`` and ``phase_deg``
``equivalent_dof``    Welch's equivalent degrees of freedom for overlapped segments
``psd_confidence``    chi-square confidence interval of a PSD from its EDOF (App. A.4)
``quantization_floor``  the ADC's white quantization noise density q^2 dt / 12 (App. A.7)

and the older helpers ``band_rms``, ``dip_frequency``, ``dip_depth_db``.

References
----------
.. [Klinger] R. Klinger, *Error Modeling of Precision Orientation Sensors in a Fixed Base
   Simulator*, Stanford, 1974: Ch. IV D-G (eqs. 4.12-4.50) and App. A.
.. [Welch] P. D. Welch, "The use of fast Fourier transform for the estimation of power
   spectra: a method based on time averaging over short, modified periodograms", IEEE
   Trans. Audio Electroacoust. AU-15 (2), 70-73, 1967 (the thesis's [W2]).
.. [BP] J. S. Bendat and A. G. Piersol, *Random Data: Analysis and Measurement
   Procedures*, Wiley (1971; 4th ed. 2010), the chapters on statistical errors of spectral
   estimates: chi-square intervals for autospectra, random error of coherence and of
   frequency-response estimates (the thesis's [B2]).
.. [Widrow] B. Widrow, "Statistical analysis of amplitude-quantized sampled-data systems",
   AIEE Trans. Appl. Ind. 79, 555-568, 1961 (the thesis's [W3]).
"""

from __future__ import annotations

import warnings
from typing import Literal

import numpy as np
import scipy.fft
import scipy.signal
import scipy.stats

__all__ = [
    "band_rms",
    "coherence",
    "coherence_pair",
    "dip_depth_db",
    "dip_frequency",
    "equivalent_dof",
    "gain",
    "n_segments",
    "phase_deg",
    "psd",
    "psd_confidence",
    "quantization_floor",
    "transfer_h1",
    "welch_csd_matrix",
]

Scaling = Literal["density", "spectrum"]
Sides = Literal["onesided", "twosided"]
DEFAULT_NPERSEG = 256  # scipy.signal's default for a named window


# ----------------------------------------------------------------------------- segmentation


def _window_and_sizes(
    window, nperseg: int | None, noverlap: int | None, nfft: int | None, n: int
) -> tuple[np.ndarray, int, int, int]:
    """The window array and (nperseg, noverlap, nfft), triaged exactly as ``scipy.signal.csd``.

    A named window (str or tuple for ``scipy.signal.get_window``; periodic, as scipy's) gets
    ``nperseg`` samples, 256 by default, cut to the record length with a warning; an array
    window sets ``nperseg`` to its length.
    """
    if isinstance(window, (str, tuple)):
        nperseg = int(nperseg) if nperseg is not None else DEFAULT_NPERSEG
        if nperseg < 1:
            raise ValueError(f"nperseg={nperseg} is not a positive integer")
        if n < nperseg:
            warnings.warn(
                f"nperseg={nperseg} is greater than the record length {n}, using nperseg={n}",
                stacklevel=3,
            )
            nperseg = n
        win = scipy.signal.get_window(window, nperseg)
    else:
        win = np.asarray(window, dtype=float)
        if win.ndim != 1:
            raise ValueError("window must be 1-D")
        if nperseg is None:
            nperseg = len(win)
        if nperseg != len(win):
            raise ValueError(f"nperseg={nperseg} does not equal the window's length {len(win)}")
        if n < nperseg:
            raise ValueError(f"the window ({nperseg}) is longer than the record ({n})")
    nfft = int(nfft) if nfft is not None else nperseg
    if nfft < nperseg:
        raise ValueError(f"nfft={nfft} must be at least nperseg={nperseg}")
    noverlap = int(noverlap) if noverlap is not None else nperseg // 2
    if not 0 <= noverlap < nperseg:
        raise ValueError(f"noverlap={noverlap} must be in [0, nperseg={nperseg})")
    return win, nperseg, noverlap, nfft


def n_segments(n_samples: int, nperseg: int, noverlap: int) -> int:
    """Number of segments Welch's method (and scipy) takes from ``n_samples``: segment k
    covers samples ``k D .. k D + nperseg - 1`` with ``D = nperseg - noverlap``; a tail
    shorter than a segment is left out."""
    return (n_samples - noverlap) // (nperseg - noverlap)


def _detrended_segments(x: np.ndarray, nperseg: int, noverlap: int, detrend) -> np.ndarray:
    """All segments of all rows of ``x`` (..., n) as a new array (..., K, nperseg), detrended.

    The segments are a strided view of ``x`` (no copy); detrending (or, without it, the
    explicit copy) makes the one array that the window and the FFT then work on in place.
    """
    step = nperseg - noverlap
    seg = np.lib.stride_tricks.sliding_window_view(x, nperseg, axis=-1)[..., ::step, :]
    if detrend is False or detrend is None:
        return np.array(seg, dtype=np.result_type(seg, np.float64))
    if detrend not in ("constant", "linear"):
        raise ValueError(f"detrend={detrend!r} must be 'constant', 'linear' or False")
    d = seg - seg.mean(axis=-1, keepdims=True)
    if detrend == "linear":
        # least-squares line: with t centred, the slope is <d, t> / <t, t> (mean already gone)
        t = np.arange(nperseg) - 0.5 * (nperseg - 1)
        slope = (d @ t) / (t @ t)
        d -= slope[..., None] * t
    return d


def _segment_ffts(
    x: np.ndarray,
    fs: float,
    win: np.ndarray,
    nperseg: int,
    noverlap: int,
    nfft: int,
    detrend,
    sides: str,
) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies and the FFTs (..., K, n_freq) of the windowed, detrended segments of ``x``."""
    d = _detrended_segments(x, nperseg, noverlap, detrend)
    d *= win
    if sides == "onesided":
        return scipy.fft.rfftfreq(nfft, 1.0 / fs), scipy.fft.rfft(
            d, n=nfft, axis=-1, overwrite_x=True
        )
    return scipy.fft.fftfreq(nfft, 1.0 / fs), scipy.fft.fft(d, n=nfft, axis=-1, overwrite_x=True)


def _check(scaling: str, sides: str, x: np.ndarray) -> None:
    if scaling not in ("density", "spectrum"):
        raise ValueError(f"scaling={scaling!r} must be 'density' or 'spectrum'")
    if sides not in ("onesided", "twosided"):
        raise ValueError(f"sides={sides!r} must be 'onesided' or 'twosided'")
    if sides == "onesided" and np.iscomplexobj(x):
        raise ValueError("complex data has no one-sided spectrum: use sides='twosided'")


def _scale(win: np.ndarray, fs: float, scaling: str) -> float:
    """scipy's normalization: density 1 / (fs sum w^2) (eq. 4.16 with App. A.2's mean square
    window u = sum w^2 / N), spectrum 1 / (sum w)^2 (a sinusoid's power at its bin)."""
    return 1.0 / (fs * float(win @ win)) if scaling == "density" else 1.0 / float(win.sum()) ** 2


def _double_one_sided(S: np.ndarray, nfft: int) -> None:
    """Fold the negative frequencies onto the positive ones in place (axis 0 = frequency):
    every bin but DC and, for even nfft, the unpaired Nyquist bin is doubled."""
    S[1 : None if nfft % 2 else -1] *= 2.0


# ----------------------------------------------------------------------------- estimators


def welch_csd_matrix(
    x,
    fs: float = 1.0,
    *,
    window="hann",
    nperseg: int | None = None,
    noverlap: int | None = None,
    nfft: int | None = None,
    detrend="constant",
    scaling: Scaling = "density",
    sides: Sides = "onesided",
) -> tuple[np.ndarray, np.ndarray]:
    r"""Welch estimate of the full cross-spectral matrix of N channels.

    Parameters
    ----------
    x : array_like, shape (n_channels, n_samples)
        One row per channel, all sampled together (a sequence of equal-length 1-D arrays
        is stacked; a 1-D array is one channel). Real, or complex with ``sides='twosided'``.
    fs : float
        Sampling frequency (Hz).
    window : str, tuple or array_like
        As ``scipy.signal.get_window`` (periodic), or the window's samples.
    nperseg, noverlap, nfft : int, optional
        Segment length (default 256 for a named window), overlap (default ``nperseg // 2``)
        and FFT length (default ``nperseg``; longer zero-pads).
    detrend : {'constant', 'linear', False}
        Removed from each segment before the window (App. A.3 removes a line from the
        whole record instead: see ``daq.prewhiten``).
    scaling : {'density', 'spectrum'}
        Density in units^2/Hz, or power spectrum in units^2 (a sinusoid of amplitude A at
        a bin reads A^2/2 one-sided).
    sides : {'onesided', 'twosided'}
        One-sided: f = 0 .. fs/2, every bin but DC (and the Nyquist bin for even ``nfft``)
        doubled. Two-sided: the ``numpy.fft.fftfreq`` order (0, positive, then negative
        frequencies), as scipy's ``return_onesided=False``.

    Returns
    -------
    f : ndarray, shape (n_freq,)
    S : ndarray, complex, shape (n_freq, n_channels, n_channels)
        ``S[:, i, j]`` equals ``scipy.signal.csd(x[i], x[j], ...)`` and ``S[:, i, i]`` (real
        up to its exactly zeroed imaginary part) ``scipy.signal.welch(x[i], ...)``.
        Each ``S[k]`` is Hermitian and positive semi-definite.

    Notes
    -----
    Segment ``k`` of channel ``i``, detrended and windowed by ``w``, has the DFT
    :math:`X_{ik}(n) = \sum_m w(m) x_i(kD + m) e^{-j 2\pi nm/N_{fft}}`, ``D = nperseg -
    noverlap``. The modified periodograms of eqs. 4.16/4.41 with App. A.2's window
    normalization are averaged over the K segments (App. A.4, [Welch]):

    .. math:: S_{ij}(n) = \frac{c}{K} \sum_{k=0}^{K-1} X_{ik}^*(n) X_{jk}(n),

    with :math:`c = 1 / (f_s \sum w^2)` (density) or :math:`1 / (\sum w)^2` (spectrum), and a
    factor 2 for the one-sided bins that stand for a +-f pair. All channels' segments are
    cut from one strided view, detrended, windowed and transformed in one FFT call; the N x N
    products are one batched matrix product per frequency. ``scipy.signal.coherence`` for
    one pair transforms each signal twice more (its two ``welch`` and one ``csd`` calls), so
    the N (N - 1) / 2 pairs cost 2 N (N - 1) channel transforms against N here. Memory: the
    segments (real) and their transforms (complex, twice: as computed and frequency-major)
    each take about N K nperseg values, twice the record at 50 % overlap.
    """
    x = np.asarray(x)
    if x.ndim == 1:
        x = x[None, :]
    if x.ndim != 2:
        raise ValueError(f"x must be (n_channels, n_samples), got shape {x.shape}")
    _check(scaling, sides, x)
    win, nperseg, noverlap, nfft = _window_and_sizes(window, nperseg, noverlap, nfft, x.shape[-1])
    f, X = _segment_ffts(x, fs, win, nperseg, noverlap, nfft, detrend, sides)
    K = X.shape[1]
    Xf = np.ascontiguousarray(X.transpose(2, 0, 1))  # (n_freq, N, K)
    S = np.matmul(Xf.conj(), Xf.transpose(0, 2, 1))  # eq. 4.41 summed over segments
    S *= _scale(win, fs, scaling) / K
    if sides == "onesided":
        _double_one_sided(S, nfft)
    idx = np.arange(x.shape[0])
    S[:, idx, idx] = S[:, idx, idx].real  # autospectra are real (eq. 4.16)
    return f, S


def psd(
    x,
    fs: float,
    seg_s: float = 8.0,
    *,
    nperseg: int | None = None,
    window="hann",
    noverlap: int | None = None,
    nfft: int | None = None,
    detrend="linear",
    scaling: Scaling = "density",
    sides: Sides = "onesided",
) -> tuple[np.ndarray, np.ndarray]:
    """Welch PSD (eq. 4.16 averaged, App. A.4): one-sided density (units^2/Hz) by default.

    The project's default: Hann segments of ``seg_s`` seconds (cut to the record), 50 %
    overlap, a line removed from each segment. Any keyword overrides it; with them all given
    the result equals ``scipy.signal.welch(x, fs, window, nperseg, noverlap, nfft, detrend,
    return_onesided=(sides == 'onesided'), scaling=scaling)``.

    ``x`` is 1-D, or 2-D with one channel per row (then ``p`` has a row per channel).
    Returns ``(f, p)`` with ``p`` real; two-sided in ``numpy.fft.fftfreq`` order.
    """
    x = np.asarray(x)
    _check(scaling, sides, x)
    if nperseg is None and isinstance(window, (str, tuple)):
        nperseg = min(x.shape[-1], round(seg_s * fs))
    win, nperseg, noverlap, nfft = _window_and_sizes(window, nperseg, noverlap, nfft, x.shape[-1])
    f, X = _segment_ffts(x, fs, win, nperseg, noverlap, nfft, detrend, sides)
    p = np.mean(X.real**2 + X.imag**2, axis=-2) * _scale(win, fs, scaling)
    if sides == "onesided":
        p = np.moveaxis(p, -1, 0)
        _double_one_sided(p, nfft)
        p = np.moveaxis(p, 0, -1)
    return f, p


def coherence(S: np.ndarray) -> np.ndarray:
    r"""Magnitude-squared coherence of every pair from a cross-spectral matrix (eq. 4.44, 4.49).

    .. math:: \gamma_{ij}^2(f) = \frac{|S_{ij}(f)|^2}{S_{ii}(f) S_{jj}(f)}

    ``S`` is ``(n_freq, N, N)`` as from ``welch_csd_matrix``; returns the real
    ``(n_freq, N, N)`` array (ones on the diagonal, nan where an autospectrum is zero). It
    equals ``scipy.signal.coherence`` pair by pair with the same Welch options.

    Averaging matters: from one segment the estimate is identically 1 (eq. 4.50). With K
    independent segments and no true coherence its expected value is about 1/K ([BP]), the
    floor against which a coherent line (Ch. IV I) has to stand out.
    """
    S = np.asarray(S)
    d = np.real(np.diagonal(S, axis1=-2, axis2=-1))  # (n_freq, N)
    with np.errstate(divide="ignore", invalid="ignore"):
        return (S.real**2 + S.imag**2) / (d[..., :, None] * d[..., None, :])


def coherence_pair(x, y, fs: float = 1.0, **welch_kw) -> tuple[np.ndarray, np.ndarray]:
    """``scipy.signal.coherence(x, y, fs, ...)`` from one pass over both signals.

    ``welch_kw`` are those of ``welch_csd_matrix`` (window, nperseg, noverlap, nfft,
    detrend; one-sided, as scipy's coherence). Returns ``(f, Cxy)``.
    """
    f, S = welch_csd_matrix(np.stack([np.asarray(x), np.asarray(y)]), fs, **welch_kw)
    return f, coherence(S)[:, 0, 1]


def transfer_h1(S: np.ndarray, i_in: int, j_out) -> np.ndarray:
    r"""The H1 frequency-response estimate from input channel ``i_in`` to ``j_out`` (eq. 4.36).

    .. math:: H_1(f) = \frac{S_{xy}(f)}{S_{xx}(f)}, \quad |H| = |S_{xy}| / S_{xx}
              \ (4.37), \quad \angle H = \angle S_{xy}\ (4.38)

    with x = channel ``i_in``, y = channel ``j_out`` (an int, or a sequence of outputs:
    then the result has one column per output). Noise added at the output, uncorrelated
    with the input, leaves H1 unbiased (the thesis's remark after eq. 4.48); noise at the
    input biases it low by the coherence. Returns complex ``(n_freq,)`` or
    ``(n_freq, n_out)``; see ``gain`` and ``phase_deg``.
    """
    S = np.asarray(S)
    sxx = S[:, i_in, i_in].real
    sxy = S[:, i_in, j_out]
    return sxy / (sxx[:, None] if sxy.ndim == 2 else sxx)


def gain(H: np.ndarray) -> np.ndarray:
    """|H| (eq. 4.37)."""
    return np.abs(H)


def phase_deg(H: np.ndarray, unwrap: bool = False) -> np.ndarray:
    """Phase of H in degrees (eq. 4.38): in (-180, 180], or unwrapped along frequency (axis 0)."""
    ph = np.angle(H)
    if unwrap:
        ph = np.unwrap(ph, axis=0)
    return np.degrees(ph)


# ----------------------------------------------------------------------------- statistics


def equivalent_dof(window, nperseg: int, noverlap: int, n_segments: int) -> float:
    r"""Equivalent degrees of freedom of a Welch average of overlapped segments ([Welch]).

    Averaging K segments (App. A.4) gives a PSD estimate approximately distributed as
    :math:`S \chi^2_\nu / \nu` with :math:`\nu = 2 E^2[\hat P] / \mathrm{Var}[\hat P]`. For
    Gaussian data and a spectrum smooth over the window's bandwidth, [Welch] gives

    .. math:: \frac{\mathrm{Var}[\hat P]}{E^2[\hat P]} = \frac{1}{K}\Big[1 + 2\sum_{j=1}^{K-1}
              \frac{K - j}{K}\,\rho(j)\Big], \qquad
              \rho(j) = \frac{\big[\sum_m w(m)\,w(m + jD)\big]^2}{\big[\sum_m w^2(m)\big]^2},

    ``D = nperseg - noverlap``: :math:`\rho(j)` is the squared correlation of the periodograms
    of segments ``j`` apart, non-zero only while they overlap. So
    :math:`\nu = 2K / [1 + 2\sum_j (1 - j/K)\rho(j)]`; without overlap :math:`\nu = 2K`, the
    thesis's ``k = 2M`` (App. A.4). Hann at 50 %: the segments' windows correlate by 1/6,
    :math:`\rho(1) = 1/36`, so :math:`\nu = 2K / (1 + (1 - 1/K)/18) \to 1.89 K`: overlap buys
    almost twice the segments of the same record for a 5 % loss per segment.

    This is the count for bins strictly between DC and Nyquist. At DC and, for even
    ``nfft``, at Nyquist the periodogram of real data is chi-square with one degree of
    freedom, so the EDOF there is half this; the first bins beside them (within the
    window's main-lobe half width) fall in between.

    ``window`` is a name (as ``scipy.signal.get_window``, periodic) or the window's samples.
    """
    if isinstance(window, (str, tuple)):
        w = scipy.signal.get_window(window, nperseg)
    else:
        w = np.asarray(window, dtype=float)
        if len(w) != nperseg:
            raise ValueError(f"the window has {len(w)} samples, nperseg is {nperseg}")
    if not 0 <= noverlap < nperseg:
        raise ValueError(f"noverlap={noverlap} must be in [0, nperseg={nperseg})")
    K = int(n_segments)
    if K < 1:
        raise ValueError("n_segments must be at least 1")
    step = nperseg - noverlap
    ww = float(w @ w)
    acc = 0.0
    for j in range(1, K):
        lag = j * step
        if lag >= nperseg:
            break
        rho = (float(w[:-lag] @ w[lag:]) / ww) ** 2
        acc += (1.0 - j / K) * rho
    return 2.0 * K / (1.0 + 2.0 * acc)


def psd_confidence(S, dof, level: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
    r"""Two-sided confidence interval of a PSD estimate from its equivalent degrees of freedom.

    With :math:`\nu \hat P / P \sim \chi^2_\nu` (App. A.4; [BP]), for :math:`\alpha = 1 -`
    ``level``:

    .. math:: \frac{\nu \hat P}{\chi^2_{\nu;\,1-\alpha/2}} \le P \le
              \frac{\nu \hat P}{\chi^2_{\nu;\,\alpha/2}}

    where :math:`\chi^2_{\nu;p}` is the p-quantile. ``S`` is the estimate (any shape, real;
    an autospectrum), ``dof`` the EDOF (``equivalent_dof``; a scalar or an array that
    broadcasts, e.g. halved at DC). Returns ``(lower, upper)``. The interval is the same
    factor of the estimate at every frequency: a constant band on a log plot.
    """
    if not 0.0 < level < 1.0:
        raise ValueError("level must be in (0, 1)")
    S = np.asarray(S, dtype=float)
    dof = np.asarray(dof, dtype=float)
    a = 1.0 - level
    lower = dof * S / scipy.stats.chi2.ppf(1.0 - a / 2.0, dof)
    upper = dof * S / scipy.stats.chi2.ppf(a / 2.0, dof)
    return lower, upper


def quantization_floor(range_V: float, bits: int, fs: float, sides: Sides = "onesided") -> float:
    r"""Density of an ADC's quantization noise (App. A.7, [Widrow]), in V^2/Hz.

    A converter spanning ``-range_V .. +range_V`` with ``bits`` bits has the step
    :math:`q = 2\,\mathrm{range} / 2^{bits}`; its roundoff is white, uniform on
    :math:`\pm q/2`, of variance :math:`q^2/12`. Spread over :math:`-f_s/2 .. f_s/2` that is
    the thesis's two-sided density :math:`P = q^2 \Delta t / 12` (``sides='twosided'``). The
    one-sided density of this module's PSDs (``sides='onesided'``, the default) is twice
    that, :math:`q^2 \Delta t / 6`: its integral over 0 .. fs/2 is the same q^2/12.
    """
    if sides not in ("onesided", "twosided"):
        raise ValueError(f"sides={sides!r} must be 'onesided' or 'twosided'")
    q = 2.0 * range_V / 2.0**bits
    two_sided = q * q / (12.0 * fs)
    return 2.0 * two_sided if sides == "onesided" else two_sided


# ----------------------------------------------------------------------------- features


def band_rms(f: np.ndarray, p: np.ndarray, lo: float, hi: float) -> float:
    """rms of the part of a one-sided PSD between ``lo`` and ``hi`` Hz."""
    sel = (f >= lo) & (f <= hi)
    return float(np.sqrt(np.trapezoid(p[sel], f[sel])))


def _smoothed_db(f: np.ndarray, p: np.ndarray, smooth_hz: float) -> np.ndarray:
    k = max(1, int(round(smooth_hz / (f[1] - f[0]))))
    return 10 * np.convolve(np.log10(p), np.ones(k) / k, mode="same")


def dip_frequency(
    f: np.ndarray, p: np.ndarray, lo: float = 1.0, hi: float = 12.0, smooth_hz: float = 0.5
) -> float:
    """Frequency of the deepest minimum of a PSD within ``lo``..``hi`` Hz (Ch. V E.1).

    The PSD is first smoothed in log over ``smooth_hz`` so a single low estimate does not win.
    """
    db = _smoothed_db(f, p, smooth_hz)
    sel = np.nonzero((f >= lo) & (f <= hi))[0]
    return float(f[sel[np.argmin(db[sel])]])


def dip_depth_db(f: np.ndarray, p: np.ndarray, f_dip: float, smooth_hz: float = 0.5) -> float:
    """How far (dB) the PSD at ``f_dip`` lies below the lower of its values at f_dip/2 and
    1.6 f_dip: positive for a true notch, negative where the spectrum merely slopes."""
    db = _smoothed_db(f, p, smooth_hz)

    def at(x: float) -> float:
        return float(db[np.argmin(np.abs(f - x))])

    return min(at(f_dip / 2), at(1.6 * f_dip)) - at(f_dip)
