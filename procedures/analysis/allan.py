"""Allan deviation of a rate record and the gyro read-offs taken from it.

The deviations come from ``allantools`` (the overlapping Allan deviation, NIST SP 1065
eq. 11); this module only wraps it for rate data with gaps, adds confidence intervals and
reads off the IEEE 952 noise terms:

* ``allan_deviation``: overlapping Allan deviation of one or more gap-free segments of
  rate samples. Segments are pooled as one estimate: each segment's sum of squared second
  differences is added and divided by the total count (every term is an unbiased estimate
  of the Allan variance; terms never straddle a gap). Confidence intervals use Greenhall's
  equivalent degrees of freedom (``allantools.edf_greenhall``, overlapping ADEV, d = 2) for
  the power-law noise identified at each averaging time by the lag-1 autocorrelation
  method (``allantools.autocorr_noise_id``, Riley and Greenhall 2004), and the chi-square
  interval ``allantools.confidence_interval`` (NIST SP 1065 eq. 45). The noise ID needs at
  least 30 averages; longer averaging times keep the last identified type, so their
  intervals are approximate.
* ``read_arw``: angle random walk N, the white-rate term, from the tau^-1/2 line
  sigma(tau) = N / sqrt(tau) through a stated tau range (IEEE Std 952-1997, Annex C: N is
  the line's value at tau = 1 s). The line's slope fitted freely is returned too: if it is
  not near -1/2 the range is not a white-rate region, and N is then only an upper bound,
  because every other noise term adds to the Allan variance.
* ``read_bias_instability``: B = (minimum of the Allan deviation) / 0.664 (IEEE 952
  Annex C: flicker rate noise of one-sided PSD B^2 / (pi f) has the flat Allan floor
  sqrt(2 ln 2 / pi) B = 0.664 B). The minimum is taken over averaging times with enough
  degrees of freedom (counted for flicker noise, what the floor is); when it is at the
  longest of them and significantly below the curve a few octaves earlier, the floor was
  not reached and B is an upper bound.
* ``fit_noise_model``: the Allan variance as a non-negative sum of the IEEE 952 terms (white and
  flicker angle noise, angle random walk, bias instability, rate random walk), weighted by the
  points' degrees of freedom; ``term_estimate`` reads one term (N or B) with a 95 % interval for
  the process' parameter at the tau the model picks, or only the model-free bound where the data
  cannot tell it from the others (the drift procedure's figures; docs/procedures/drift.md).
  ``read_arw`` and ``read_bias_instability`` are the plain IEEE 952 read-offs, kept for
  comparison: their intervals describe the sample at the point read.
* ``null_stability``: the peak-to-peak wander of block averages (the thesis' "24-hour null
  stability", Table 1) over the record, and an estimate for a longer span from the Allan
  deviation (``wander_variance``).

References: IEEE Std 952-1997 (R2008), Annex C "Allan variance method of data reduction";
W. J. Riley, *Handbook of Frequency Stability Analysis*, NIST SP 1065 (2008): eq. 11
(overlapping ADEV), eq. 45 (chi-square interval), Table 5 (flicker phase noise), its test suite
(NBS-14, pp. 107-108); F. E. Satterthwaite, "An approximate distribution of estimates of variance
components", Biometrics Bulletin 2 (1946) for the mixture's degrees of freedom;
C. A. Greenhall and W. J. Riley, "Uncertainty of stability variances based on finite
differences" (PTTI 2003) for the EDF; W. J. Riley and C. A. Greenhall, "Power law noise
identification using the lag 1 autocorrelation" (EFTF 2004).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import allantools
import numpy as np
import scipy.stats

#: IEEE 952 Annex C: the Allan floor of flicker rate noise is sqrt(2 ln 2 / pi) B
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)  # 0.6643
#: one-sigma confidence (68.27 %), as allantools' default
ONE_SIGMA = float(allantools.ci.ONE_SIGMA_CI)
#: averages the lag-1 autocorrelation noise ID needs (Riley and Greenhall 2004)
NOISE_ID_MIN_POINTS = 30


@dataclass
class AllanResult:
    """Overlapping Allan deviation with its confidence interval at each averaging time."""

    tau_s: np.ndarray
    dev: np.ndarray
    lo: np.ndarray  # lower and upper confidence limits (``ci`` level)
    hi: np.ndarray
    edf: np.ndarray  # equivalent degrees of freedom
    n_terms: np.ndarray  # second differences summed (all segments)
    alpha: np.ndarray  # power-law noise exponent used for the EDF (S_y ~ f^alpha)
    alpha_identified: np.ndarray  # True where alpha was identified at that tau (not carried over)
    rate_hz: float
    n_samples: int  # samples in all segments
    ci: float = ONE_SIGMA
    overlapping: bool = True
    segment_lengths: tuple[int, ...] = ()

    def usable(self, min_edf: float) -> np.ndarray:
        return np.isfinite(self.dev) & (self.edf >= min_edf)

    def edf_for(self, alpha: int) -> np.ndarray:
        """Greenhall EDF at every tau had the noise been of type ``alpha`` throughout."""
        return np.array(
            [
                _edf(alpha, int(round(t * self.rate_hz)), self.segment_lengths, self.overlapping)
                for t in self.tau_s
            ]
        )

    def interval(self, i: int, edf: float, ci: float | None = None) -> tuple[float, float]:
        """The interval (default: the result's ``ci`` level) of the deviation at index ``i``
        for ``edf`` degrees of freedom."""
        lo, hi = allantools.confidence_interval(self.dev[i], edf, self.ci if ci is None else ci)
        return float(lo), float(hi)


def _edf(alpha: int, m: int, lengths: Sequence[int], overlapping: bool) -> float:
    """Greenhall's EDF (``allantools.edf_greenhall``, d = 2) summed over independent segments.
    allantools lacks the white-phase (alpha = 2) case of a segment under 4 m + 1 points; there
    the flicker-phase (alpha = 1) EDF stands in."""

    def one(n: int) -> float:
        try:
            return float(
                allantools.edf_greenhall(
                    alpha=int(alpha),
                    d=2,
                    m=int(m),
                    N=int(n) + 1,
                    overlapping=overlapping,
                    modified=False,
                )
            )
        except NotImplementedError:
            return float(
                allantools.edf_greenhall(
                    alpha=1, d=2, m=int(m), N=int(n) + 1, overlapping=overlapping, modified=False
                )
            )

    return float(sum(one(n) for n in lengths if n + 1 > 2 * m))


def octave_taus(n_samples: int, rate_hz: float, max_fraction: float = 0.25) -> np.ndarray:
    """Averaging times m / rate for m = 1, 2, 4, ... up to ``max_fraction`` of the record."""
    m_max = max(1, int(n_samples * max_fraction))
    return 2.0 ** np.arange(int(math.log2(m_max)) + 1) / rate_hz


def split_finite(x: np.ndarray, min_len: int = 3) -> list[np.ndarray]:
    """The runs of finite samples of ``x`` (NaN marks lost samples), each at least ``min_len``."""
    x = np.asarray(x, float)
    ok = np.isfinite(x)
    if ok.all():
        return [x] if len(x) >= min_len else []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    return [x[a:b] for a, b in zip(edges[::2], edges[1::2]) if b - a >= min_len]


def allan_deviation(
    segments: Sequence[np.ndarray] | np.ndarray,
    rate_hz: float,
    taus: Sequence[float] | np.ndarray | None = None,
    *,
    ci: float = ONE_SIGMA,
    overlapping: bool = True,
) -> AllanResult:
    """Overlapping Allan deviation (``allantools.oadev`` on rate ("freq") data) of one
    gap-free array or of several segments pooled, with confidence intervals;
    ``overlapping=False`` gives the classic non-overlapping one (``allantools.adev``).

    ``taus`` default: octaves up to a quarter of the longest segment. A tau no segment is
    long enough for (2 m + 1 samples) is dropped.
    """
    if isinstance(segments, np.ndarray) and segments.ndim == 1:
        segments = [segments]
    segs = [np.asarray(s, float) for s in segments if len(s) >= 3]
    if not segs:
        raise ValueError("no segment of at least 3 samples")
    if any(not np.all(np.isfinite(s)) for s in segs):
        raise ValueError(
            "a segment holds NaN or inf: split the record at its gaps first (split_finite)"
        )
    longest = max(segs, key=len)
    if taus is None:
        taus = octave_taus(len(longest), rate_hz)
    m_all = np.unique(np.maximum(1, np.round(np.asarray(taus, float) * rate_hz).astype(np.int64)))
    dev_fn = allantools.oadev if overlapping else allantools.adev
    sumsq = np.zeros(len(m_all))
    count = np.zeros(len(m_all), dtype=np.int64)
    for s in segs:
        fit = m_all[2 * m_all < len(s)]  # oadev needs N_phase = len + 1 > 2 m
        if len(fit) == 0:
            continue
        t, dev, _err, ns = dev_fn(s, rate=rate_hz, data_type="freq", taus=fit / rate_hz)
        m_got = np.round(np.asarray(t) * rate_hz).astype(np.int64)
        idx = np.searchsorted(m_all, m_got)
        ns = np.asarray(ns, dtype=np.int64)
        sumsq[idx] += np.asarray(dev) ** 2 * ns
        count[idx] += ns
    keep = count > 0
    m_all, sumsq, count = m_all[keep], sumsq[keep], count[keep]
    dev = np.sqrt(sumsq / count)

    # noise type per tau (on the longest segment), then Greenhall's EDF summed over segments
    alpha = np.zeros(len(m_all), dtype=np.int64)
    identified = np.zeros(len(m_all), dtype=bool)
    last = 0  # white rate noise until something is identified
    for i, m in enumerate(m_all):
        if len(longest) // m >= NOISE_ID_MIN_POINTS:
            last = int(
                allantools.autocorr_noise_id(longest, int(m), data_type="freq", dmin=0, dmax=2)[0]
            )
            last = min(2, max(-2, last))  # the Allan variance converges for alpha > -3
            identified[i] = True
        alpha[i] = last
    lengths = tuple(len(s) for s in segs)
    edf = np.array([_edf(int(a), int(m), lengths, overlapping) for a, m in zip(alpha, m_all)])
    lo = np.full(len(m_all), np.nan)
    hi = np.full(len(m_all), np.nan)
    for k in np.flatnonzero(edf > 0):
        lo[k], hi[k] = allantools.confidence_interval(dev[k], edf[k], ci)
    return AllanResult(
        m_all / rate_hz,
        dev,
        lo,
        hi,
        edf,
        count,
        alpha,
        identified,
        rate_hz,
        sum(lengths),
        ci,
        overlapping,
        lengths,
    )


# ---------------------------------------------------------------------------- read-offs
@dataclass
class ArwReadoff:
    """White-rate (angle random walk) coefficient from the tau^-1/2 line."""

    N: float  # units / sqrt(s): sigma(1 s) of the -1/2 line
    lo: float  # confidence limits (from the best-determined point in range)
    hi: float
    tau_range_s: tuple[float, float]  # averaging times actually used
    n_points: int
    slope: float  # log-log slope fitted freely over the same points
    white_region: bool  # |slope + 1/2| <= slope_tol: a tau^-1/2 region

    @property
    def stderr(self) -> float:
        return (self.hi - self.lo) / 2


def read_arw(
    res: AllanResult,
    tau_range_s: tuple[float, float],
    *,
    min_edf: float = 10.0,
    slope_tol: float = 0.15,
) -> ArwReadoff:
    """N from the line sigma = N tau^-1/2 through the deviations with tau in ``tau_range_s``
    (IEEE 952 Annex C), fitted in log space with each point weighted by its EDF."""
    lo_t, hi_t = tau_range_s
    sel = (res.tau_s >= lo_t * (1 - 1e-9)) & (res.tau_s <= hi_t * (1 + 1e-9)) & res.usable(min_edf)
    if sel.sum() < 2:
        raise ValueError(
            f"fewer than two usable Allan points in tau {lo_t:g}..{hi_t:g} s "
            f"(record too short, or the range misses the sample interval)"
        )
    t, d, w = res.tau_s[sel], res.dev[sel], res.edf[sel]
    logn = np.log(d) + 0.5 * np.log(t)
    N = float(np.exp(np.average(logn, weights=w)))
    slope = float(np.polyfit(np.log(t), np.log(d), 1, w=np.sqrt(w))[0])
    # points of overlapping estimates are strongly correlated: the fit is no better determined
    # than its best point, whose relative interval is carried over
    best = int(np.argmax(w))
    rel_lo, rel_hi = res.lo[sel][best] / d[best], res.hi[sel][best] / d[best]
    return ArwReadoff(
        N,
        N * rel_lo,
        N * rel_hi,
        (float(t.min()), float(t.max())),
        int(sel.sum()),
        slope,
        abs(slope + 0.5) <= slope_tol,
    )


@dataclass
class BiasInstabilityReadoff:
    """Bias instability from the flat minimum of the Allan deviation."""

    B: float  # units (of the rate): sigma_min / 0.664
    lo: float
    hi: float
    tau_min_s: float  # where the minimum is
    sigma_min: float
    floor_reached: bool  # False: the minimum is at the longest usable tau, still falling
    tau_max_s: float  # longest usable tau

    @property
    def stderr(self) -> float:
        return (self.hi - self.lo) / 2


def read_bias_instability(
    res: AllanResult, *, min_edf: float = 10.0, min_tau_s: float = 0.0, back_octaves: int = 3
) -> BiasInstabilityReadoff:
    """B = min sigma / 0.664 over the averaging times >= ``min_tau_s`` where the estimate
    has at least ``min_edf`` degrees of freedom (IEEE 952 Annex C). ``min_tau_s`` keeps the
    read-off beyond where the floor can be the quantity's own (e.g. a loop's time constants).

    The degrees of freedom (and the interval) here are Greenhall's for flicker rate noise
    (alpha = -1) at every tau, the noise the floor is: the identified type is unreliable
    with the few averages of the longest taus, and a white-noise identification there
    would claim several times the degrees of freedom, letting a low outlier of the
    scatter pose as the floor. The minimum of a scattered curve still leans low, the more
    so the more points it is taken over.

    The floor counts as reached unless the minimum is at the longest usable tau *and* lies
    significantly below the curve ``back_octaves`` octaves earlier (any usable tau, the 95 %
    intervals of the two do not overlap): a curve still falling there (white rate noise falls by
    2^(-3/2) = 0.35 in three octaves) has not shown its floor, and B is then an upper
    bound. Comparing across several octaves, not one, keeps the scatter of the long-tau
    points from deciding it."""
    edf = res.edf_for(-1)
    usable = np.isfinite(res.dev) & (edf >= min_edf)
    ok = usable & (res.tau_s >= min_tau_s)
    if not ok.any():
        raise ValueError(
            f"no Allan point with EDF >= {min_edf:g} (flicker) at tau >= {min_tau_s:g} s "
            f"(record too short: the longest such tau is "
            f"{res.tau_s[usable].max() if usable.any() else 0:g} s)"
        )
    idx = np.flatnonzero(ok)
    i = idx[int(np.argmin(res.dev[idx]))]
    lo, hi = res.interval(i, edf[i])
    reached = True
    earlier = np.flatnonzero(usable & (res.tau_s < res.tau_s[i]))
    if i == idx[-1] and len(earlier):
        target = res.tau_s[i] / 2**back_octaves
        j = earlier[int(np.argmin(np.abs(np.log(res.tau_s[earlier] / target))))]
        reached = not res.interval(i, edf[i], 0.95)[1] < res.interval(j, edf[j], 0.95)[0]
    s = float(res.dev[i])
    return BiasInstabilityReadoff(
        s / FLICKER_FLOOR,
        lo / FLICKER_FLOOR,
        hi / FLICKER_FLOOR,
        float(res.tau_s[i]),
        s,
        reached,
        float(res.tau_s[idx[-1]]),
    )


# ---------------------------------------------------------------------------- null stability
def block_means(segments: Sequence[np.ndarray], rate_hz: float, avg_s: float) -> np.ndarray:
    """Means of consecutive whole blocks of ``avg_s`` within each gap-free segment."""
    m = max(1, int(round(avg_s * rate_hz)))
    out = [s[: len(s) // m * m].reshape(-1, m).mean(axis=1) for s in segments if len(s) >= m]
    return np.concatenate(out) if out else np.zeros(0)


def wander_variance(span_s: float, avg_s: float, sigma_at) -> float:
    """Expected variance, about their mean, of the ``avg_s`` averages over ``span_s``:
    half the sum of the Allan variances at avg_s, 2 avg_s, 4 avg_s, ... < span_s.

    This is the Haar decomposition of a sample variance: 2^J averages split exactly into
    differences of adjacent half-block means at each octave, and each such difference has
    expected square 2 sigma^2(tau) (non-overlapping Allan variance). ``sigma_at(tau)`` gives
    the Allan deviation at tau (measured, or extrapolated beyond the record).
    """
    n = span_s / avg_s
    if n < 2:
        return 0.0
    levels = int(math.floor(math.log2(n)))
    var = sum(sigma_at(avg_s * 2**j) ** 2 for j in range(levels))
    frac = math.log2(n) - levels  # a partial octave counts in proportion
    var += frac * sigma_at(avg_s * 2**levels) ** 2
    return 0.5 * var


@dataclass
class NullStability:
    """Peak-to-peak wander of ``avg_s`` averages (the thesis' strip-chart null stability)."""

    avg_s: float
    record_s: float  # span covered by the averages
    n_averages: int
    peak_to_peak: float  # over the record
    span_s: float  # the span the estimate is for (e.g. 24 h)
    estimate: float  # peak-to-peak expected over span_s
    measured_over_span: bool  # the record covers span_s: the estimate is a measurement
    ratio: float  # sqrt(wander variance over span / over the record)
    extrapolated_from_tau_s: float  # taus beyond this used the extrapolated Allan deviation
    extrapolation_slope: float  # log-log slope used beyond it
    means: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))


def null_stability(
    segments: Sequence[np.ndarray],
    rate_hz: float,
    res: AllanResult,
    *,
    avg_s: float = 100.0,
    span_s: float = 86400.0,
    min_edf: float = 10.0,
) -> NullStability:
    """Peak-to-peak of the ``avg_s`` means over the record, and an estimate for ``span_s``.

    If the record is shorter than ``span_s`` the peak-to-peak is scaled by the ratio of the
    expected rms wander of the averages over ``span_s`` to that over the record
    (``wander_variance``): the range-to-rms ratio of the record is assumed to carry over
    (it grows slowly with the number of averages, so this leans low). The Allan deviation
    is taken as measured up to the longest tau with ``min_edf`` degrees of freedom (for
    flicker noise, as ``read_bias_instability``) and
    continued beyond it as a power law with the slope of its last octave clamped to
    0 .. +1/2 (flat for flicker rate noise, +1/2 for rate random walk); a slow trend or
    temperature cycle the record did not see is not in the estimate.
    """
    means = block_means(segments, rate_hz, avg_s)
    if len(means) < 2:
        raise ValueError(f"fewer than two {avg_s:g}-s averages in the record")
    p2p = float(means.max() - means.min())
    record_s = len(means) * avg_s
    ok = np.isfinite(res.dev) & (res.edf_for(-1) >= min_edf)  # as read_bias_instability
    t, d = res.tau_s[ok], res.dev[ok]
    if len(t) < 2:
        raise ValueError("too few usable Allan points for the null-stability estimate")
    slope = math.log(d[-1] / d[-2]) / math.log(t[-1] / t[-2])
    slope = min(0.5, max(0.0, slope))
    t_last, d_last = float(t[-1]), float(d[-1])
    logt, logd = np.log(t), np.log(d)

    def sigma_at(tau: float) -> float:
        if tau <= t_last:
            return float(np.exp(np.interp(math.log(tau), logt, logd)))
        return d_last * (tau / t_last) ** slope

    if record_s >= span_s:
        k = int(round(span_s / avg_s))
        win = np.lib.stride_tricks.sliding_window_view(means, k)
        est = float((win.max(axis=1) - win.min(axis=1)).max())
        return NullStability(
            avg_s, record_s, len(means), p2p, span_s, est, True, 1.0, t_last, slope, means
        )
    v_rec = wander_variance(record_s, avg_s, sigma_at)
    v_span = wander_variance(span_s, avg_s, sigma_at)
    ratio = math.sqrt(v_span / v_rec) if v_rec > 0 else math.nan
    return NullStability(
        avg_s, record_s, len(means), p2p, span_s, p2p * ratio, False, ratio, t_last, slope, means
    )


# ---------------------------------------------------------------------------- noise model
#: the terms of the Allan variance of a rate record (IEEE 952 Annex C, Table C.1; NIST SP 1065
#: Table 5 for flicker angle noise), as functions of tau: white angle ("phase") noise 3 Q^2 / tau^2,
#: flicker angle noise F^2 ln(tau / tau_0) / tau^2 (SP 1065: sigma^2 = h_1 (1.038 + 3 ln(2 pi f_h
#: tau)) / (4 pi^2 tau^2), the constant part going into the white term; tau_0 half the shortest
#: tau fitted, so that both coefficients are >= 0 over the fit), angle random walk N^2 / tau, bias
#: instability (0.664 B)^2, rate random walk K^2 tau / 3
TERMS = ("angle", "flicker_angle", "arw", "bias", "rrw")
#: the power-law exponent alpha (S_y ~ f^alpha) of each term, for Greenhall's EDF
TERM_ALPHA = {"angle": 2, "flicker_angle": 1, "arw": 0, "bias": -1, "rrw": -2}
#: the weighted least squares' covariance treats the Allan points as independent; the octave
#: points of one overlapping estimate are not, and on 30 synthetic 2-h records (white angle,
#: white rate and flicker rate noise) the coefficients scattered 1.0..1.6 times the standard
#: deviations it gives: the covariance is scaled by the square of the larger
COV_INFLATION = 1.6**2
#: a term is read where its share of the modelled variance is at least this fraction of its
#: largest share (and, among those taus, where it is best determined: ``term_estimate``)
SHARE_NEAR_MAX = 0.95
#: the nuisance terms the fit drops when the data do not need them (``fit_noise_model``); the
#: gyro's own N and B stay, so that a term present but not distinguishable widens the others'
#: intervals instead of biasing them
DROPPABLE = ("flicker_angle", "rrw")
#: the terms whose one-sided limit is the fit's (``term_estimate``): the model-free bound of a term
#: under the others is a ceiling (N under the angle noise and B: on the drawn rigs of
#: bench/coverage_all.py 2-10x the truth, holding it 137 times in 137). B's basis is flat, so its
#: bound is taken where B is read and is tight already; the fit's limit for it would inherit the
#: model's misfit at the longest taus (bench/drift_coverage.py: on Z, with the platform's azimuth
#: wander, it held B 20 times in 27, the bound 26 in 28)
MODEL_LIMIT_TERMS = ("arw",)


def _basis(tau: np.ndarray, tau0: float) -> np.ndarray:
    tau = np.asarray(tau, float)
    return np.column_stack(
        [
            3.0 / tau**2,
            np.log(tau / tau0) / tau**2,
            1.0 / tau,
            np.full(len(tau), FLICKER_FLOOR**2),
            tau / 3.0,
        ]
    )


@dataclass
class NoiseModel:
    """The Allan variance as a sum of the terms ``TERMS``, fitted with non-negative
    coefficients: ``coef`` = (Q^2, F^2, N^2, B^2, K^2), so that
    sigma^2(tau) = 3 Q^2 / tau^2 + F^2 ln(tau / tau0) / tau^2 + N^2 / tau + 0.664^2 B^2 + K^2 tau / 3."""

    coef: np.ndarray
    tau0_s: float
    tau_fit_s: np.ndarray  # the averaging times fitted
    #: covariance of ``coef`` (the weighted least squares' (A^T W A)^-1 over the terms fitted
    #: above zero and the non-droppable ones, times ``COV_INFLATION``; zero rows and columns
    #: for the dropped)
    cov: np.ndarray = field(default_factory=lambda: np.zeros((len(TERMS), len(TERMS))))

    def basis(self, tau: np.ndarray | float) -> np.ndarray:
        return _basis(np.atleast_1d(np.asarray(tau, float)), self.tau0_s)

    def variance(self, tau: np.ndarray | float, term: str | None = None) -> np.ndarray:
        b = self.basis(tau)
        if term is None:
            return b @ self.coef
        j = TERMS.index(term)
        return b[:, j] * self.coef[j]

    def others_sd(self, term: str, tau: float) -> float:
        """Standard deviation of the other terms' modelled variance at ``tau`` (from ``cov``)."""
        g = self.basis(tau)[0]
        g[TERMS.index(term)] = 0.0
        return math.sqrt(max(float(g @ self.cov @ g), 0.0))

    def share(self, term: str, tau: np.ndarray | float) -> np.ndarray:
        """The fraction of the modelled Allan variance at ``tau`` that is ``term``'s."""
        total = self.variance(tau)
        return np.where(total > 0, self.variance(tau, term) / np.where(total > 0, total, 1.0), 0.0)


def _wnnls(
    a: np.ndarray, v: np.ndarray, nu: np.ndarray, use: np.ndarray, iterations: int
) -> tuple[np.ndarray, np.ndarray, float]:
    """Iteratively reweighted non-negative least squares on the columns ``use``: the
    coefficients, the model values and the weighted sum of squares (chi-square units)."""
    from scipy.optimize import nnls

    scale = a.max(axis=0)
    m = v.copy()
    coef = np.zeros(a.shape[1])
    for _ in range(iterations):
        w = np.sqrt(nu / 2.0) / m
        c, _ = nnls(a[:, use] / scale[use] * w[:, None], v * w)
        coef = np.zeros(a.shape[1])
        coef[use] = c / scale[use]
        m = np.maximum(a @ coef, 1e-3 * v)
    return coef, m, float(np.sum(nu / 2.0 * ((v - m) / m) ** 2))


def fit_noise_model(
    res: AllanResult,
    *,
    min_tau_s: float = 0.0,
    min_edf: float = 2.0,
    iterations: int = 4,
    keep_chi2: float = 3.84,
) -> NoiseModel:
    """Non-negative weighted least squares of the Allan variances at tau >= ``min_tau_s`` on the
    terms ``TERMS``. An Allan variance estimate with nu degrees of freedom has variance
    2 sigma^4 / nu (chi-square), so each point is weighted nu / (2 m^2), m the model's value
    there (iterated from the measured value): a relative fit, where every point counts by
    its degrees of freedom.

    A nuisance term (``DROPPABLE``) stays only if the data need it: such terms are dropped one at
    a time, the one whose removal raises the weighted sum of squares least, while that rise (divided by
    ``COV_INFLATION`` for the points' correlation) is under ``keep_chi2`` (chi-square, one
    degree of freedom, 95 %). So a term the record cannot tell from the others (a rate random
    walk in a short record, which a flicker floor's scatter imitates) does not take a share of
    the variance and widen every other term's interval."""
    sel = np.isfinite(res.dev) & (res.edf >= min_edf) & (res.tau_s >= min_tau_s * (1 - 1e-9))
    if sel.sum() < len(TERMS):
        raise ValueError(
            f"fewer than {len(TERMS)} usable Allan points at tau >= {min_tau_s:g} s for the noise model"
        )
    tau, v, nu = res.tau_s[sel], res.dev[sel] ** 2, res.edf[sel]
    tau0 = 0.5 * float(tau.min())
    a = _basis(tau, tau0)
    use = np.ones(len(TERMS), dtype=bool)
    droppable = np.array([t in DROPPABLE for t in TERMS])
    coef, m, ssr = _wnnls(a, v, nu, use, iterations)
    use = coef > 0
    while use.sum() > 1:
        trials = []
        for j in np.flatnonzero(use & droppable):
            u = use.copy()
            u[j] = False
            trials.append((_wnnls(a, v, nu, u, iterations), u))
        if not trials:
            break
        (c2, m2, ssr2), u2 = min(trials, key=lambda t: t[0][2])
        if (ssr2 - ssr) / COV_INFLATION >= keep_chi2:
            break
        coef, m, ssr, use = c2, m2, ssr2, u2 & (c2 > 0)
    w = nu / (2.0 * m**2)
    # the covariance over the terms fitted above zero and the gyro's own terms even where they
    # sit at zero: a term the fit put at zero may still hold variance the others would then lose
    active = (coef > 0) | ~droppable
    cov = np.zeros((len(TERMS), len(TERMS)))
    if active.any():
        scale = a.max(axis=0)
        aa = a[:, active] / scale[active]
        inv = np.linalg.pinv(aa.T @ (aa * w[:, None]))
        cov[np.ix_(active, active)] = COV_INFLATION * inv / np.outer(scale[active], scale[active])
    return NoiseModel(coef, tau0, tau, cov)


@dataclass
class TermEstimate:
    """One noise term's coefficient (N for ``arw``, B for ``bias``) with its 95 % interval.

    ``value`` is NaN when the data show none of the term (its share of the model is nil, or
    the measured variance at ``tau_s`` is all the other terms'); ``lo``..``hi`` are then
    0 .. ``upper`` (``MODEL_LIMIT_TERMS``) or 0 .. ``bound``.

    ``upper`` is the one-sided upper limit at the interval's level, what an unresolved figure
    reports (0 .. ``upper``, issue 38: an unresolved bound is a 95 % bound, not a ceiling);
    ``bound`` holds whatever the model, the smallest of Bonferroni-corrected limits on the whole
    measured variance."""

    term: str
    value: float
    lo: float
    hi: float
    tau_s: float  # the averaging time read (NaN: none)
    share: float  # the term's share of the modelled variance there
    bound: float  # the model-free upper bound (every other term adds variance)
    why: str = ""
    upper: float = math.nan  # the one-sided limit, for ``MODEL_LIMIT_TERMS`` (NaN: none)

    @property
    def upper_limit(self) -> float:
        """``upper``, or ``hi`` where none was computed."""
        return self.upper if math.isfinite(self.upper) else self.hi


def mixed_edf(res: AllanResult, model: NoiseModel) -> np.ndarray:
    """Degrees of freedom of the Allan variance at every tau for the fitted mixture of noises:
    Satterthwaite's nu = (sum v_t)^2 / sum (v_t^2 / nu_t), v_t each term's modelled variance and
    nu_t Greenhall's EDF for its noise type (a sum of independent scaled chi-squares taken as
    one). The flicker-angle term takes flicker phase's (alpha = 1), 148 at tau 204.8 s of a
    2400 s record at 10 Hz, where white phase's is 10,800."""
    v = np.column_stack([model.variance(res.tau_s, t) for t in TERMS])
    nus = np.column_stack([res.edf_for(TERM_ALPHA[t]) for t in TERMS])
    num = v.sum(axis=1) ** 2
    den = np.sum(np.where(v > 0, v**2 / np.where(nus > 0, nus, np.inf), 0.0), axis=1)
    return np.where(den > 0, num / np.where(den > 0, den, 1.0), res.edf)


def term_estimate(
    res: AllanResult,
    model: NoiseModel,
    term: str,
    *,
    min_edf: float = 10.0,
    min_tau_s: float = 0.0,
    level: float = 0.95,
) -> TermEstimate:
    """The coefficient of ``term`` (``arw``: N, ``bias``: B) with a ``level`` interval for the
    gyro's parameter, not for the sample.

    The averaging time read is, among those where the term has at least ``SHARE_NEAR_MAX`` of
    its largest share of the modelled variance, the one where it is best determined: the
    smallest ratio of the standard deviation of (measured variance - other terms' modelled
    variance) to the term's modelled variance, the measured variance's from the noise mixture's
    degrees of freedom there (``mixed_edf``, at least ``min_edf``), the others' from the fit's
    covariance. It is chosen by the smooth model, not by the scattered data, so a low outlier of
    the curve cannot select itself (the minimum of the curve, IEEE 952's read-off, leans low and
    its interval describes that one sample). There the measured Allan variance s^2 has the chi-square interval (NIST
    SP 1065 eq. 45) of the mixture's degrees of freedom, an interval for the process' Allan
    variance; the other terms' modelled variance is subtracted from s^2, the uncertainty of
    that (``NoiseModel.others_sd``) is added in quadrature to each side, and the rest divided by
    the term's basis function.

    The model-free bound: every independent noise adds Allan variance, so the term's variance
    is at most the upper limit of the measured variance at every tau; the smallest of these
    (``bound``, Bonferroni-corrected over the taus, each with the fewer of the mixture's and the
    term's own noise type's degrees of freedom) caps the interval.

    The one-sided limit (``upper``, at ``level``, for ``MODEL_LIMIT_TERMS``): read at the same
    tau with the two-sided interval at 2 level - 1; for a term the fit put at zero, its
    coefficient's z-level limit from the fit's covariance (``NoiseModel.cov``); neither above
    the bound. A term with no share in the model, or whose estimate is not positive, has value
    NaN and the interval 0 .. ``upper`` (0 .. ``bound`` for the other terms)."""
    j = TERMS.index(term)
    edf = mixed_edf(res, model)
    ok = np.isfinite(res.dev) & (edf >= min_edf) & (res.tau_s >= min_tau_s * (1 - 1e-9))
    if not ok.any():
        raise ValueError(f"no Allan point with EDF >= {min_edf:g} at tau >= {min_tau_s:g} s")
    idx = np.flatnonzero(ok)
    basis = model.basis(res.tau_s[idx])[:, j]
    # Bonferroni: the bound is the smallest of len(idx) upper limits, so each is taken at the
    # level that keeps the chance of any one falling below the truth at 1 - level
    # the degrees of freedom of the term's own noise type where fewer than the mixture's: the
    # bound must hold if the model has the term wrong (or none of it)
    edf_b = np.minimum(edf, res.edf_for(TERM_ALPHA[term]))
    level_each = 1.0 - (1.0 - level) / len(idx)
    upper = np.array([res.interval(i, edf_b[i], level_each)[1] ** 2 for i in idx.tolist()]) / basis
    bound_c = float(upper.min())

    def coefficient(c: float) -> float:  # the figure from the model coefficient
        return math.sqrt(max(c, 0.0))

    bound = coefficient(bound_c)
    # the fit's one-sided limit: the coefficient (>= 0) plus z of its standard deviation, from
    # the fit's covariance, which carries the trade with the terms beside it; not above the bound
    z1 = float(scipy.stats.norm.ppf(level))
    sd_fit = math.sqrt(max(float(model.cov[j, j]), 0.0))
    from_model = term in MODEL_LIMIT_TERMS
    upper_fit = (
        coefficient(min(max(float(model.coef[j]), 0.0) + z1 * sd_fit, bound_c))
        if from_model and sd_fit > 0
        else bound
    )
    shares = model.share(term, res.tau_s[idx])
    if model.coef[j] <= 0 or shares.max() <= 0:
        return TermEstimate(
            term,
            math.nan,
            0.0,
            upper_fit,
            math.nan,
            0.0,
            bound,
            "the fitted noise model has none of it: an upper bound only",
            upper_fit if from_model else math.nan,
        )
    # the tau where the term's variance is best determined: the standard deviation of the
    # measured variance (sqrt(2 / nu) m, m the model's variance) and of the other terms' modelled
    # variance, in quadrature, relative to the term's variance
    m_all = model.variance(res.tau_s[idx])
    own = model.variance(res.tau_s[idx], term)
    sd = np.sqrt(
        2.0 / edf[idx] * m_all**2
        + np.array([model.others_sd(term, t) ** 2 for t in res.tau_s[idx]])
    )
    # among the taus where the term has near its largest share (the model's shape is least
    # relied on there)
    near = shares >= SHARE_NEAR_MAX * shares.max()
    k = int(np.argmin(np.where(near & (own > 0), sd / np.where(own > 0, own, 1.0), np.inf)))
    i = int(idx[k])
    others = float(model.variance(res.tau_s[i])[0] - model.variance(res.tau_s[i], term)[0])
    s2 = float(res.dev[i]) ** 2
    lo, hi = res.interval(i, edf[i], level)
    # the other terms' modelled variance is uncertain too: its half-width added in quadrature
    # to each side of the chi-square interval
    z = float(scipy.stats.norm.ppf(0.5 + level / 2))
    sd_oth = model.others_sd(term, res.tau_s[i])
    d_oth = z * sd_oth
    c_val = (s2 - others) / basis[k]
    c_lo = c_val - math.hypot(s2 - lo**2, d_oth) / basis[k]
    c_hi = c_val + math.hypot(hi**2 - s2, d_oth) / basis[k]
    # the one-sided limit read there: the upper end of the two-sided interval at 2 level - 1
    _, hi1 = res.interval(i, edf[i], 2.0 * level - 1.0)
    c_up = c_val + math.hypot(hi1**2 - s2, z1 * sd_oth) / basis[k]
    if bound_c > c_val:  # the bound caps the interval, unless this point lies above it
        c_hi, c_up = min(c_hi, bound_c), min(c_up, bound_c)
    tau = float(res.tau_s[i])
    if c_val <= 0:
        # nothing left once the others' modelled variance is off: the term is bounded by what the
        # fit and this point allow it, the larger of the two limits
        up = max(upper_fit, coefficient(c_up)) if from_model else bound
        return TermEstimate(
            term,
            math.nan,
            0.0,
            up,
            tau,
            float(shares[k]),
            bound,
            f"at tau {tau:g} s the measured variance is all the other terms': an upper bound only",
            up if from_model else math.nan,
        )
    return TermEstimate(
        term,
        coefficient(c_val),
        coefficient(c_lo),
        coefficient(c_hi),
        tau,
        float(shares[k]),
        bound,
        upper=coefficient(c_up) if from_model else math.nan,
    )
