"""Open-loop sensor baselines (thesis Ch. V B, Figs. 32-34, Table 1): the numbers, no rig.

With the platform clamped and the loops open, what each sensor records is its own noise:

* **Autocollimator NEA** (Table 1, Ch. V B.3): the rms angle in 0.1-100 Hz, the square root
  of the area under the channel's one-sided PSD over the band (the thesis doubles its two-sided
  area), volts turned into urad with the channel's scale. The band's lowest bins are the 1/f
  part's, so the Welch segment must reach 0.1 Hz with four bins to spare
  (``BlockCsd.lowest_fit_hz``); the interval is a delete-one jackknife over blocks of the
  record (Student's t, blocks - 1 degrees of freedom), which sees the 1/f bins' scatter as it is.
* **White level and 1/f corner** (Fig. 32): the angle noise's PSD, the channel's filter
  divided out (eqs. 3.21-3.22), fitted as S_w (1 + f_c / f) by least squares weighted by the
  model's own level (a Welch PSD's scatter is proportional to it); jackknife intervals.
* **Gyro pickoff** (Fig. 33): the rms in bands, and its discrete lines: peaks standing far above
  the running median of the averaged PSD, each measured on the whole record
  (``procedures.analysis.lines.refine_line``: frequency, its 1-sigma, amplitude).
* **Azimuth autocollimator** (Fig. 34): its NEA as the primary's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.ndimage

from daq.spectra import n_segments, welch_csd_matrix
from procedures.analysis.intervals import Estimate, from_stderr
from procedures.analysis.lines import refine_line
from procedures.analysis.transfer import BlockCsd, jackknife_se

#: Table 1 quotes the NEA in this band
NEA_BAND_HZ = (0.1, 100.0)
#: the pickoff's bands: 1-50 Hz beside the excitation's incoherent pickoff noise (no lines
#: there), 0.1-200 Hz as Ch. V B quotes the pickoff noise (lines included)
PICKOFF_BANDS_HZ: dict[str, tuple[float, float]] = {"1-50 Hz": (1.0, 50.0), "0.1-200 Hz": (0.1, 200.0)}
#: a pickoff line stands this far above the running median of the averaged PSD; an average of
#: K Welch segments exceeds m times its mean with probability ~ exp(-K m): never at 20
LINE_MIN_RATIO = 20.0
#: the running median's width, and the least spacing of two lines (the 71 Hz pair is ~0.8 Hz apart)
LINE_MEDIAN_HZ = 2.0
LINE_MIN_SEPARATION_HZ = 0.35


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
        return Estimate(nan, nan, nan, False, f"the band starts at {lo:g} Hz, below the {blocks.lowest_fit_hz:.3g} Hz "
                                              f"{blocks.seg_s:g} s Welch segments resolve (use segments >= {4 / lo:g} s)")
    return None


def band_rms(blocks: BlockCsd, channel: str, scale_V_per_urad: float, lo_hz: float, hi_hz: float) -> Estimate:
    """rms (urad) of ``channel`` in ``lo..hi`` Hz: sqrt of the PSD's sum over the band's bins
    times the bin width, over the channel's scale; jackknife interval over the blocks."""
    if (bad := _unreachable(blocks, lo_hz)) is not None:
        return bad
    if hi_hz > blocks.fs / 2:
        nan = float("nan")
        return Estimate(nan, nan, nan, False, f"the band reaches {hi_hz:g} Hz, above the Nyquist frequency "
                                              f"{blocks.fs / 2:g} Hz")
    i = blocks.index(channel)
    band = _band(blocks.f, lo_hz, hi_hz)
    df = float(blocks.f[1] - blocks.f[0])

    def rms(leave_out: int | None) -> float:
        p = blocks.mean(leave_out)[:, i, i].real
        return math.sqrt(float(np.sum(p[band])) * df) / scale_V_per_urad

    return _jackknifed(blocks, rms)


@dataclass(frozen=True)
class WhiteFlicker:
    """The angle noise S_w (1 + f_c / f): white level (urad/sqrt(Hz)) and 1/f corner (Hz)."""

    white_urad_per_rtHz: Estimate
    corner_hz: Estimate


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


def white_flicker(blocks: BlockCsd, channel: str, scale_V_per_urad: float, filter_gain2: np.ndarray,
                  lo_hz: float, hi_hz: float) -> WhiteFlicker:
    """Fit the angle noise of an autocollimator channel (``filter_gain2`` its filter's |H|^2 at
    ``blocks.f``) over ``lo..hi`` Hz (the band where the filter passes, above the quantization
    floor: the thesis's white band reaches 35 Hz on the control channel, 80 Hz on the
    instrumentation channel, Ch. V B.3)."""
    i = blocks.index(channel)
    band = _band(blocks.f, max(lo_hz, blocks.lowest_fit_hz), hi_hz) & (blocks.f > 0)
    f = blocks.f[band]

    def fit(leave_out: int | None) -> tuple[float, float]:
        p = blocks.mean(leave_out)[band, i, i].real / (scale_V_per_urad ** 2 * filter_gain2[band])
        return fit_white_flicker(f, p)

    a, b = fit(None)
    loo = np.array([fit(k) for k in range(blocks.n_blocks)])
    dof = blocks.n_blocks - 1
    white = from_stderr(math.sqrt(max(a, 0.0)), float(jackknife_se(np.sqrt(np.maximum(loo[:, 0], 0.0)))), dof=dof)
    corner_value = b / a if a > 0 else float("nan")
    with np.errstate(divide="ignore", invalid="ignore"):
        corners = loo[:, 1] / loo[:, 0]
    se = float(jackknife_se(corners)) if np.all(np.isfinite(corners)) else float("nan")
    corner = from_stderr(corner_value, se, dof=dof)   # unresolved when its interval reaches zero
    return WhiteFlicker(white, corner)


# ---------------------------------------------------------------------------- lines
@dataclass(frozen=True)
class Line:
    """A discrete line of the pickoff spectrum, measured on the whole record."""

    freq_hz: float
    freq_sigma_hz: float
    amplitude_urad: float       # peak amplitude (biased up by the noise in its bin)
    ratio: float                # its averaged-PSD peak over the running median around it

    @property
    def ci95_hz(self) -> tuple[float, float]:
        return self.freq_hz - 1.96 * self.freq_sigma_hz, self.freq_hz + 1.96 * self.freq_sigma_hz


def line_peaks(f: np.ndarray, p: np.ndarray, lo_hz: float, hi_hz: float, *, min_ratio: float = LINE_MIN_RATIO,
               median_hz: float = LINE_MEDIAN_HZ, min_separation_hz: float = LINE_MIN_SEPARATION_HZ
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


def pickoff_lines(x: np.ndarray, rate_hz: float, f: np.ndarray, p: np.ndarray, kg_V_per_urad: float,
                  lo_hz: float, hi_hz: float, **kw) -> list[Line]:
    """The lines of the pickoff record ``x`` (V) whose averaged PSD is ``p`` (V^2/Hz at ``f``):
    found by ``line_peaks``, each measured on the whole record within two Welch bins of its peak;
    in frequency order."""
    df = float(f[1] - f[0])
    x = np.asarray(x, float)
    if not np.all(np.isfinite(x)):   # lost samples: the record's mean, so the time base holds
        x = np.where(np.isfinite(x), x, np.nanmean(x))
    out = []
    for f0, ratio, noise in line_peaks(f, p, lo_hz, hi_hz, **kw):
        m = refine_line(x, rate_hz, f0, 2.0 * df, noise)
        if not m.is_line:
            continue  # a resonance or a noise band, as wide as itself: not a line
        out.append(Line(m.freq_hz, m.sigma_hz, m.amplitude / kg_V_per_urad, ratio))
    return sorted(out, key=lambda ln: ln.freq_hz)


def array_blocks(x: np.ndarray, rate_hz: float, channels: Sequence[str], seg_s: float, n_blocks: int) -> BlockCsd:
    """``BlockCsd`` of an in-memory record ``x`` (samples x channels) as ``block_csd`` makes it
    of a file: ``n_blocks`` consecutive blocks, Welch (Hann, 50 % overlap, a line removed per
    segment) in each."""
    nperseg = int(round(seg_s * rate_hz))
    n = len(x)
    if n < nperseg * n_blocks or n_blocks < 3:
        raise ValueError(f"{n / rate_hz:g} s of record holds fewer than {n_blocks} (>= 3) blocks of one {seg_s:g} s "
                         f"segment")
    edges = [(n * k) // n_blocks for k in range(n_blocks + 1)]
    S, w = [], []
    f = np.empty(0)
    for a, b in zip(edges[:-1], edges[1:]):
        f, s = welch_csd_matrix(np.asarray(x[a:b], float).T, rate_hz, nperseg=nperseg, noverlap=nperseg // 2,
                                detrend="linear")
        S.append(s)
        w.append(float(n_segments(b - a, nperseg, nperseg // 2)))
    return BlockCsd(f, np.array(S), np.array(w), tuple(channels), float(rate_hz), seg_s, n / rate_hz)


def psd_of(blocks: BlockCsd, channel: str) -> np.ndarray:
    """The block-averaged PSD of ``channel`` (units^2/Hz, one-sided)."""
    i = blocks.index(channel)
    return blocks.mean()[:, i, i].real


def nea_truth(f: np.ndarray, angle_psd: np.ndarray, filter_gain2: np.ndarray,
              band: Sequence[float] = NEA_BAND_HZ) -> float:
    """rms (same units as sqrt(angle_psd x Hz)) of an angle noise of one-sided PSD
    ``angle_psd`` seen through a filter |H|^2 over ``band``: the NEA a model predicts."""
    sel = _band(f, band[0], band[1])
    return math.sqrt(float(np.trapezoid((angle_psd * filter_gain2)[sel], f[sel])))
