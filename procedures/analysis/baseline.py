"""Open-loop sensor baselines (thesis Ch. V B, Figs. 32-34, Table 1): the numbers, no rig.

With the platform clamped and the loops open, what each sensor records is its own noise:

* **Autocollimator NEA** (Table 1, Ch. V B.3): the rms angle in 0.1-100 Hz, the square root
  of the area under the channel's one-sided PSD over the band (the thesis doubles its two-sided
  area), volts turned into urad with the channel's scale. The band's lowest bins are the 1/f
  part's, so the Welch segment must reach 0.1 Hz with four bins to spare
  (``BlockCsd.lowest_fit_hz``); the interval is a delete-one jackknife over blocks of the
  record (Student's t, blocks - 1 degrees of freedom), which sees the 1/f bins' scatter as it is.
* **White level and 1/f corner** (Fig. 32): the angle noise's PSD, the channel's filter and
  the recorder's anti-alias filter divided out (eqs. 3.21-3.22, App. A.5), fitted as
  S_w (1 + f_c / f) by least squares weighted by the model's own level (a Welch PSD's scatter
  is proportional to it); jackknife intervals.
* **Physical rms** (the NEA, the pickoff's band rms): the recorder's 3-pole anti-alias
  low-pass at 0.3 fs (DESIGN.md section 5, App. A.5; ``anti_alias_gain2``) divided out of the
  PSD before its area is taken (issue 38: the pickoff's 0.1-200 Hz rms read 0.01-0.41 % low, its
  lines at 187 Hz cut by 3 %), with the filter's corner known to +-``ANTI_ALIAS_CORNER_TOL``
  in the interval.
* **Gyro pickoff** (Fig. 33): the rms in bands, and its discrete lines: peaks standing far above
  the running median of the averaged PSD, each measured on the whole record
  (``procedures.analysis.lines.refine_line``: frequency, its 1-sigma, amplitude).
* **Azimuth autocollimator** (Fig. 34): its NEA as the primary's.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.ndimage

from daq.spectral import n_segments, welch_csd_matrix
from drivers.rig_datasheet import AutocollimatorConstants
from procedures.analysis.intervals import LEVEL, Estimate, from_stderr, judged
from procedures.analysis.lines import refine_line
from procedures.analysis.transfer import BlockCsd, jackknife_se, sensor_filter

#: Table 1 quotes the NEA in this band
NEA_BAND_HZ = (0.1, 100.0)
#: the pickoff's bands: 1-50 Hz beside the excitation's incoherent pickoff noise (no lines
#: there), 0.1-200 Hz as Ch. V B quotes the pickoff noise (lines included)
PICKOFF_BANDS_HZ: dict[str, tuple[float, float]] = {
    "1-50 Hz": (1.0, 50.0),
    "0.1-200 Hz": (0.1, 200.0),
}
#: a pickoff line stands this far above the running median of the averaged PSD; an average of
#: K Welch segments exceeds m times its mean with probability ~ exp(-K m): never at 20
LINE_MIN_RATIO = 20.0
#: the running median's width, and the least spacing of two lines (the 71 Hz pair is ~0.8 Hz apart)
LINE_MEDIAN_HZ = 2.0
LINE_MIN_SEPARATION_HZ = 0.35
#: the recorder's anti-alias filter (DESIGN.md section 5; App. A.5 "three-pole active low-pass
#: filters ... approximately 30 percent of the sampling frequency"): poles, corner / fs
ANTI_ALIAS_POLES, ANTI_ALIAS_FRACTION = 3, 0.3
#: how well its corner is known (95 %): an active filter of 5 % parts, and an analogue filter
#: realised digitally (bilinear, corner prewarped) sits 5 % off at 0.19 fs with 2x oversampling
ANTI_ALIAS_CORNER_TOL = 0.10


def anti_alias_gain2(f: np.ndarray, fs: float, corner_scale: float = 1.0) -> np.ndarray:
    """|H(f)|^2 of the recorder's anti-alias filter, a ``ANTI_ALIAS_POLES``-pole Butterworth at
    ``ANTI_ALIAS_FRACTION`` fs (its corner times ``corner_scale``): 1 / (1 + (f / f_c)^(2 n))
    (the Butterworth magnitude; App. A.5, DESIGN.md section 5)."""
    fc = ANTI_ALIAS_FRACTION * fs * corner_scale
    return 1.0 / (1.0 + (np.asarray(f, float) / fc) ** (2 * ANTI_ALIAS_POLES))


def _band(f: np.ndarray, lo: float, hi: float) -> np.ndarray:
    return (f >= lo - 1e-9) & (f <= hi + 1e-9)


def _jackknifed(blocks: BlockCsd, fn) -> Estimate:
    value = fn(None)
    loo = np.array([fn(b) for b in range(blocks.n_blocks)])
    return from_stderr(value, float(jackknife_se(loo)), dof=blocks.n_blocks - 1)


def _unreachable(blocks: BlockCsd, lo: float) -> Estimate | None:
    """An unresolved figure when the band starts below what the segments resolve."""
    if lo < blocks.lowest_fit_hz - 1e-9:
        nan = float("nan")
        return Estimate(
            nan,
            nan,
            nan,
            False,
            f"the band starts at {lo:g} Hz, below the {blocks.lowest_fit_hz:.3g} Hz "
            f"{blocks.seg_s:g} s Welch segments resolve (use segments >= {4 / lo:g} s)",
        )
    return None


def band_rms(
    blocks: BlockCsd,
    channel: str,
    scale_V_per_urad: float,
    lo_hz: float,
    hi_hz: float,
    *,
    anti_alias: bool = True,
) -> Estimate:
    """rms (urad) of ``channel`` in ``lo..hi`` Hz: sqrt of the PSD's sum over the band's bins
    times the bin width, over the channel's scale; with ``anti_alias`` the recorder's filter
    (``anti_alias_gain2``) divided out of each bin first, so the figure is the sensor's rms.
    The interval: the jackknife's over the blocks (Student's t), its half-width combined in
    quadrature with the change the filter's corner tolerance (``ANTI_ALIAS_CORNER_TOL``) makes."""
    if (bad := _unreachable(blocks, lo_hz)) is not None:
        return bad
    if hi_hz > blocks.fs / 2:
        nan = float("nan")
        return Estimate(
            nan,
            nan,
            nan,
            False,
            f"the band reaches {hi_hz:g} Hz, above the Nyquist frequency {blocks.fs / 2:g} Hz",
        )
    i = blocks.index(channel)
    band = _band(blocks.f, lo_hz, hi_hz)
    df = float(blocks.f[1] - blocks.f[0])
    fb = blocks.f[band]

    def gain(scale: float) -> np.ndarray:
        return anti_alias_gain2(fb, blocks.fs, scale) if anti_alias else np.ones(len(fb))

    def rms(leave_out: int | None, g2: np.ndarray | None = None) -> float:
        p = blocks.mean(leave_out)[band, i, i].real
        return (
            math.sqrt(float(np.sum(p / (gain(1.0) if g2 is None else g2))) * df) / scale_V_per_urad
        )

    stat = _jackknifed(blocks, rms)
    if not anti_alias or not math.isfinite(stat.value):
        return stat
    tol = ANTI_ALIAS_CORNER_TOL
    aa = 0.5 * abs(rms(None, gain(1.0 + tol)) - rms(None, gain(1.0 - tol)))
    half = math.hypot(stat.half_width, aa)
    return judged(stat.value, stat.value - half, stat.value + half)


@dataclass(frozen=True)
class WhiteFlicker:
    """The angle noise S_w (1 + f_c / f): white level (urad/sqrt(Hz)) and 1/f corner (Hz)."""

    white_urad_per_rtHz: Estimate
    #: the corner over every knee form the data do not reject, its interval the union of theirs
    #: (``white_flicker``): unresolved where the record cannot tell the forms' corners apart
    corner_hz: Estimate
    #: the thesis form's corner alone (S_w (1 + f_c/f)) with its jackknife interval: a diagnostic
    corner_thesis_form: Estimate | None = None


def fit_white_flicker(f: np.ndarray, p: np.ndarray) -> tuple[float, float]:
    """(S_w, S_w f_c) of p(f) = S_w + S_w f_c / f, least squares weighted by the model's level
    (a Welch PSD's standard deviation is proportional to its mean), three passes."""
    X = np.column_stack([np.ones_like(f), 1.0 / f])
    w = np.full(len(f), 1.0 / max(float(np.median(p)), 1e-300))
    coef = np.zeros(2)
    for _ in range(3):
        coef = np.linalg.lstsq(X * w[:, None], p * w, rcond=None)[0]
        model = X @ coef
        w = 1.0 / np.maximum(model, 1e-3 * max(float(np.median(p)), 1e-300))
    return float(coef[0]), float(coef[1])


#: the knee's forms a nominal unit allows (DESIGN.md section 8: any knee between
#: ``max(1, fc/f)`` and ``1 + fc/f``, slope -0.8 .. -1.2), on a grid: each is fitted, and the
#: figures' intervals span every form the data do not reject (``white_flicker``)
KNEE_GRID = tuple(k / 8 for k in range(9))
SLOPE_GRID = tuple(0.8 + 0.05 * k for k in range(9))
#: the fit's residuals are averaged in this many log-frequency bands a decade to see a misfit no
#: form of the grid holds (the Birge ratio of ``white_flicker``)
MISFIT_BANDS_PER_DECADE = 10
#: the Hann window's bin-to-bin correlation of a PSD estimate: a sum over n adjacent bins holds
#: the information of n / HANN_BIN_FACTOR independent ones (the window's DFT -1/4, 1/2, -1/4)
HANN_BIN_FACTOR = 1.0 + 2.0 * ((2.0 / 3.0) ** 2 + (1.0 / 6.0) ** 2)
#: the corner's search, in ln f_c: this many points from a fifth of the band's start to half its top
_CORNER_GRID_POINTS = 64


def knee_shape(
    f: np.ndarray, corner_hz: float | np.ndarray, knee: float, slope: float
) -> np.ndarray:
    """K(f) of the angle noise W K(f): r = (f_c / f)^slope, K = knee (1 + r) + (1 - knee) max(1, r)
    (DESIGN.md section 8: knee 1 is the thesis's 1 + f_c/f at slope 1, knee 0 the sharp corner).
    ``corner_hz`` may be a column of corners (one row of K each)."""
    r = (np.asarray(corner_hz, float) / f) ** slope
    return knee * (1.0 + r) + (1.0 - knee) * np.maximum(1.0, r)


@dataclass(frozen=True)
class FormFit:
    """The Whittle fit of W K(f) at one knee and slope: W, f_c, and the fit's
    L = sum(p / m + ln m) (minus the log-likelihood, per unit of half the bins' dof)."""

    knee: float
    slope: float
    white: float
    corner_hz: float
    misfit: float


def fit_form(
    f: np.ndarray,
    p: np.ndarray,
    knee: float,
    slope: float,
    corner_range: tuple[float, float] | None = None,
) -> FormFit:
    """W and f_c of p(f) = W K(f) (``knee_shape`` at ``knee``, ``slope``) by the Whittle
    likelihood (a Welch PSD bin is its mean times chi^2_nu / nu): for each f_c, W = mean(p / K)
    and L = n + n ln W + sum ln K; f_c on a grid in ln f_c (``corner_range``, default a fifth of
    the band's start to half its top), then refined between the best point's neighbours."""
    import scipy.optimize

    lo, hi = corner_range if corner_range is not None else (0.2 * float(f[0]), 0.5 * float(f[-1]))
    n = len(f)

    def objective(ln_fc: np.ndarray) -> np.ndarray:
        K = knee_shape(f, np.exp(ln_fc)[:, None], knee, slope)
        W = np.mean(p / K, axis=1)
        return n + n * np.log(W) + np.sum(np.log(K), axis=1)

    grid = np.linspace(math.log(lo), math.log(hi), _CORNER_GRID_POINTS)
    j = int(np.argmin(objective(grid)))
    a, b = grid[max(j - 1, 0)], grid[min(j + 1, len(grid) - 1)]
    res = scipy.optimize.minimize_scalar(
        lambda x: float(objective(np.array([x]))[0]),
        bounds=(a, b),
        method="bounded",
        options={"xatol": 1e-5},
    )
    ln_fc = float(res.x) if res.fun <= objective(grid[j : j + 1])[0] else float(grid[j])
    fc = math.exp(ln_fc)
    K = knee_shape(f, fc, knee, slope)
    W = float(np.mean(p / K))
    return FormFit(knee, slope, W, fc, float(np.sum(p / (W * K) + np.log(W * K))))


def misfit_ratio(f: np.ndarray, rho: np.ndarray, bin_var: float, n_params: int) -> float:
    """The Birge ratio chi^2 / dof (at least 1) of a fit's relative residuals ``rho`` averaged in
    ``MISFIT_BANDS_PER_DECADE`` log-frequency bands: a band's mean of n bins scatters by
    ``bin_var`` / n where the model holds (``bin_var`` a bin's variance times the window's
    correlation factor); dof = bands - ``n_params``. Above 1 the data hold a misfit no fitted
    form explains, and every interval widens by its square root."""
    n_bands = max(n_params + 2, int(round(math.log10(f[-1] / f[0]) * MISFIT_BANDS_PER_DECADE)))
    edges = np.geomspace(f[0], f[-1] * (1 + 1e-9), n_bands + 1)
    which = np.clip(np.searchsorted(edges, f, side="right") - 1, 0, n_bands - 1)
    chi2, used = 0.0, 0
    for b in range(n_bands):
        r = rho[which == b]
        if len(r):
            chi2 += float(np.mean(r)) ** 2 * len(r) / bin_var
            used += 1
    return max(1.0, chi2 / max(used - n_params, 1))


def white_flicker(
    blocks: BlockCsd,
    channel: str,
    scale_V_per_urad: float,
    filter_gain2: np.ndarray,
    lo_hz: float,
    hi_hz: float,
) -> WhiteFlicker:
    """Fit the angle noise of an autocollimator channel (``filter_gain2`` its filter's |H|^2 at
    ``blocks.f``; the recorder's anti-alias filter, ``anti_alias_gain2``, is divided out here
    too) over ``lo..hi`` Hz (the band where the filter passes, above the quantization floor:
    the thesis's white band reaches 35 Hz on the control channel, 80 Hz on the instrumentation
    channel, Ch. V B.3).

    The value is the thesis's S_w (1 + f_c / f) (``fit_white_flicker``). Its interval holds what
    the noise model cannot know (issue 38): the knee's form and slope of a nominal unit (DESIGN.md
    section 8). Every form of ``KNEE_GRID`` x ``SLOPE_GRID`` is fitted (``fit_form``) and its
    deviance from the best form taken, D = (2 / (v h)) (L - L_min), v the best fit's relative
    residual variance (2 / nu) and h ``HANN_BIN_FACTOR``. Each form the data do not reject
    (D < chi^2_1(95 %)) gives the figure's jackknife interval over the blocks (Student's t,
    blocks - 1 dof), narrowed to sqrt(1 - D / chi^2_1(95 %)) of its half-width: the profile
    likelihood over the forms, in which a form's misfit uses up its share of the 95 %. The
    figure's interval is the union. The thesis's value stands when its form is among those not
    rejected (D < chi^2_2(95 %): knee and slope are two parameters), else the best form's; the
    value's own form always gives its whole jackknife interval.

    The corner (``corner_hz``) is the same union over the forms, unresolved when wider than
    itself: it covers the harness's corners 37-39 of 40, where the thesis fit's jackknife
    interval alone (``corner_thesis_form``) covered 18-19; on a plain 1 + f_c/f record of
    320 s it is often unresolved, honestly: a sharp knee's corner is another number the data
    do not reject."""
    import scipy.stats

    i = blocks.index(channel)
    band = _band(blocks.f, max(lo_hz, blocks.lowest_fit_hz), hi_hz) & (blocks.f > 0)
    f = blocks.f[band]
    gain2 = filter_gain2[band] * anti_alias_gain2(f, blocks.fs)

    def spectrum(leave_out: int | None) -> np.ndarray:
        return blocks.mean(leave_out)[band, i, i].real / (scale_V_per_urad**2 * gain2)

    p = spectrum(None)
    dof = blocks.n_blocks - 1
    q = float(scipy.stats.t.ppf(0.5 + LEVEL / 2, dof))
    c = float(scipy.stats.chi2.ppf(LEVEL, 1))
    forms = [fit_form(f, p, k, s) for k in KNEE_GRID for s in SLOPE_GRID]
    best = min(forms, key=lambda g: g.misfit)
    rho = p / (best.white * knee_shape(f, best.corner_hz, best.knee, best.slope)) - 1.0
    v = float(np.var(rho, ddof=4))
    birge = misfit_ratio(f, rho, v * HANN_BIN_FACTOR, n_params=4)
    dev = {g: 2.0 * (g.misfit - best.misfit) / (v * HANN_BIN_FACTOR * birge) for g in forms}

    a, b = fit_white_flicker(f, p)
    thesis = next(g for g in forms if g.knee == 1.0 and g.slope == 1.0)
    if dev[thesis] < float(scipy.stats.chi2.ppf(LEVEL, 2)) and a > 0:
        w_value, fc_value = math.sqrt(a), b / a
    else:
        w_value, fc_value = math.sqrt(best.white), best.corner_hz
    w_lo = w_hi = w_value
    fc_lo = fc_hi = fc_value if math.isfinite(fc_value) else best.corner_hz
    spectra = [spectrum(k) for k in range(blocks.n_blocks)]
    for g, d in dev.items():
        if d >= c and not (g is thesis and w_value == math.sqrt(a)):
            continue
        rng = (0.2 * g.corner_hz, 5.0 * g.corner_hz)
        loo = [fit_form(f, s, g.knee, g.slope, rng) for s in spectra]
        # the value's own form keeps its whole jackknife interval
        shrink = math.sqrt((1.0 if g is thesis else max(0.0, 1.0 - d / c)) * birge)
        hw = q * shrink * float(jackknife_se(np.sqrt([x.white for x in loo])))
        hc = q * shrink * float(jackknife_se(np.log([x.corner_hz for x in loo])))
        w = math.sqrt(g.white)
        w_lo, w_hi = min(w_lo, w - hw), max(w_hi, w + hw)
        fc_lo, fc_hi = (
            min(fc_lo, g.corner_hz * math.exp(-hc)),
            max(fc_hi, g.corner_hz * math.exp(hc)),
        )
    # the thesis form's own corner and jackknife interval, kept as a diagnostic
    loo_thesis = np.array([fit_white_flicker(f, s) for s in spectra])
    with np.errstate(divide="ignore", invalid="ignore"):
        corners = loo_thesis[:, 1] / loo_thesis[:, 0]
    se = float(jackknife_se(corners)) if np.all(np.isfinite(corners)) else float("nan")
    corner = from_stderr(b / a if a > 0 else float("nan"), se, dof=dof)
    return WhiteFlicker(judged(w_value, w_lo, w_hi), judged(fc_value, fc_lo, fc_hi), corner)


# ---------------------------------------------------------------------------- lines
@dataclass(frozen=True)
class Line:
    """A discrete line of the pickoff spectrum, measured on the whole record."""

    freq_hz: float
    freq_sigma_hz: float
    amplitude_urad: float  # peak amplitude (biased up by the noise in its bin)
    ratio: float  # its averaged-PSD peak over the running median around it

    @property
    def ci95_hz(self) -> tuple[float, float]:
        return self.freq_hz - 1.96 * self.freq_sigma_hz, self.freq_hz + 1.96 * self.freq_sigma_hz


def line_peaks(
    f: np.ndarray,
    p: np.ndarray,
    lo_hz: float,
    hi_hz: float,
    *,
    min_ratio: float = LINE_MIN_RATIO,
    median_hz: float = LINE_MEDIAN_HZ,
    min_separation_hz: float = LINE_MIN_SEPARATION_HZ,
) -> list[tuple[float, float, float]]:
    """(frequency, peak over running median, the median) of the peaks of an averaged PSD that
    stand at least ``min_ratio`` above the running median of ``median_hz`` around them, the
    strongest first, none closer than ``min_separation_hz`` to a stronger one (a Hann window's
    sidelobes beyond that are 60 dB down)."""
    df = float(f[1] - f[0])
    size = max(3, int(round(median_hz / df)) | 1)
    med = scipy.ndimage.median_filter(p, size=size, mode="nearest")
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(med > 0, p / med, 0.0)
    inner = np.zeros(len(p), bool)
    inner[1:-1] = (p[1:-1] >= p[:-2]) & (p[1:-1] >= p[2:])
    cand = np.flatnonzero(inner & _band(f, lo_hz, hi_hz) & (ratio >= min_ratio))
    out: list[tuple[float, float, float]] = []
    for j in cand[np.argsort(-p[cand])]:
        if all(abs(f[j] - g) >= min_separation_hz for g, _, _ in out):
            out.append((float(f[j]), float(ratio[j]), float(med[j])))
    return out


def pickoff_lines(
    x: np.ndarray,
    rate_hz: float,
    f: np.ndarray,
    p: np.ndarray,
    kg_V_per_urad: float,
    lo_hz: float,
    hi_hz: float,
    **kw,
) -> list[Line]:
    """The lines of the pickoff record ``x`` (V) whose averaged PSD is ``p`` (V^2/Hz at ``f``):
    found by ``line_peaks``, each measured on the whole record within two Welch bins of its peak;
    in frequency order."""
    df = float(f[1] - f[0])
    x = np.asarray(x, float)
    if not np.all(np.isfinite(x)):  # lost samples: the record's mean, so the time base holds
        x = np.where(np.isfinite(x), x, np.nanmean(x))
    out = []
    for f0, ratio, noise in line_peaks(f, p, lo_hz, hi_hz, **kw):
        m = refine_line(x, rate_hz, f0, 2.0 * df, noise)
        if not m.is_line:
            continue  # a resonance or a noise band, as wide as itself: not a line
        out.append(Line(m.freq_hz, m.sigma_hz, m.amplitude / kg_V_per_urad, ratio))
    return sorted(out, key=lambda ln: ln.freq_hz)


def array_blocks(
    x: np.ndarray, rate_hz: float, channels: Sequence[str], seg_s: float, n_blocks: int
) -> BlockCsd:
    """``BlockCsd`` of an in-memory record ``x`` (samples x channels) as ``block_csd`` makes it
    of a file: ``n_blocks`` consecutive blocks, Welch (Hann, 50 % overlap, a line removed per
    segment) in each."""
    nperseg = int(round(seg_s * rate_hz))
    n = len(x)
    if n < nperseg * n_blocks or n_blocks < 3:
        raise ValueError(
            f"{n / rate_hz:g} s of record holds fewer than {n_blocks} (>= 3) blocks of one {seg_s:g} s "
            f"segment"
        )
    edges = [(n * k) // n_blocks for k in range(n_blocks + 1)]
    S, w = [], []
    f = np.empty(0)
    for a, b in zip(edges[:-1], edges[1:]):
        f, s = welch_csd_matrix(
            np.asarray(x[a:b], float).T,
            rate_hz,
            nperseg=nperseg,
            noverlap=nperseg // 2,
            detrend="linear",
        )
        S.append(s)
        w.append(float(n_segments(b - a, nperseg, nperseg // 2)))
    return BlockCsd(
        f, np.array(S), np.array(w), tuple(channels), float(rate_hz), seg_s, n / rate_hz
    )


def psd_of(blocks: BlockCsd, channel: str) -> np.ndarray:
    """The block-averaged PSD of ``channel`` (units^2/Hz, one-sided)."""
    i = blocks.index(channel)
    return blocks.mean()[:, i, i].real


def nea_truth(
    f: np.ndarray,
    angle_psd: np.ndarray,
    filter_gain2: np.ndarray,
    band: Sequence[float] = NEA_BAND_HZ,
) -> float:
    """rms (same units as sqrt(angle_psd x Hz)) of an angle noise of one-sided PSD
    ``angle_psd`` seen through a filter |H|^2 over ``band``: the NEA a model predicts."""
    sel = _band(f, band[0], band[1])
    return math.sqrt(float(np.trapezoid((angle_psd * filter_gain2)[sel], f[sel])))


#: the white band of each autocollimator channel's fit (Ch. V B.3: 3-35 Hz control, 3-80 Hz
#: instrumentation; the fit starts at 0.1 Hz so the 1/f part is in it)
WHITE_HI_HZ = {"ctl": 35.0, "inst": 80.0}


def baseline_figures(
    blocks: BlockCsd,
    ac: AutocollimatorConstants,
    names: Mapping[str, str],
    scales_V_per_urad: Mapping[str, float],
) -> dict[str, Estimate]:
    """The baseline's figures of a clamped record's blocks, keyed ``figure.key``: the NEA of the
    control, instrumentation and azimuth channels (``names`` "ctl", "inst", "z"), the white level
    and 1/f corner of the first two (``ac``'s filters), the pickoff's (``names["gyro"]``) rms in
    ``PICKOFF_BANDS_HZ``; ``scales_V_per_urad`` per key."""
    f = blocks.f
    out: dict[str, Estimate] = {}
    for k in ("ctl", "inst", "z"):
        out[f"nea_urad.{k}"] = band_rms(blocks, names[k], scales_V_per_urad[k], *NEA_BAND_HZ)
    for k in ("ctl", "inst"):
        fit = white_flicker(
            blocks,
            names[k],
            scales_V_per_urad[k],
            np.abs(sensor_filter(f, ac, names[k])) ** 2,
            NEA_BAND_HZ[0],
            WHITE_HI_HZ[k],
        )
        out[f"white_urad_per_rtHz.{k}"] = fit.white_urad_per_rtHz
        out[f"flicker_corner_hz.{k}"] = fit.corner_hz
    for band, (lo, hi) in PICKOFF_BANDS_HZ.items():
        out[f"pickoff_rms_urad.{band}"] = band_rms(
            blocks, names["gyro"], scales_V_per_urad["gyro"], lo, hi
        )
    return out
