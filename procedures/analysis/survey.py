"""The survey numerics (thesis Ch. V E, Figs. 42-49): from one Welch cross-spectral matrix of a
Mode-3 record of the primary autocollimator's control and instrumentation channels and the X-Y
gyro's pickoffs (``daq.filespectra.run_csd_matrix``, averaged over the record's file spans by
``spans_csd``), the dip of each control-channel spectrum, the gyro-deduced platform rms and the
coherences. Files, arrays and the data sheet in, plain dataclasses out; no rig. The procedure
that records is ``procedures.calibrations.survey``; the report's text and plots are
``procedures.reports.survey``.

* **the dip** of each autocollimator control-channel spectrum (Ch. V E.1, Figs. 42/45):
  within the loop bandwidth the closed-loop response to autocollimator noise is about
  ``1/H(s)``, so a resonance in the feedback path, the platform inertia on the gimbal
  bearings' spring (Ch. V F), shows as a notch near ``sqrt(k/I)/2 pi``. Found by
  ``find_dip``: the PSD in dB is smoothed over ``dip_smooth_hz``; of the local minima in
  ``dip_lo_hz .. dip_hi_hz`` the one of largest prominence (how far it lies below the
  lower of the highest points between it and a deeper minimum or the band edge on either
  side, as ``scipy.signal.find_peaks``) is the dip; a least-squares parabola through the
  smoothed dB within +-``dip_smooth_hz`` of it refines its frequency below the bin spacing.
  The prominence is reported as the dip's depth; a depth under ``min_dip_depth_db`` fails
  (no notch: the frequency is then meaningless). The bearing stiffness the dip implies,
  ``I (2 pi f_dip)^2`` with the data sheet's inertia, is reported beside it.

* **the gyro-deduced platform rms** (Ch. V E.2), exactly the thesis's method:

      platform_rms = sqrt( integral over band_lo_hz .. band_hi_hz of S_g(f) / Kg^2 df )

  with ``S_g`` the one-sided PSD of the gyro pickoff (volts; gyro X for platform X, gyro Y
  for platform Y) and ``Kg`` its pickoff scale factor. The band is 0.4-15 Hz by default:
  the thesis had no data below 0.4 Hz, and above 15 Hz the platform does not respond to
  autocollimator noise (Fig. 26c), so it takes the power below 15 Hz as the platform's
  variance "at frequencies greater than 0.4 Hz", i.e. as the platform rms over the whole
  band above 0.4 Hz (0.4-200 Hz). The estimate credits *everything* the pickoff reports in
  the band to platform motion, pickoff noise included: what it measures is
  ``sqrt(true platform rms^2 + pickoff noise rms^2)`` in the band (docs/simhw.md section 6,
  docs/procedures/survey.md). ``Kg`` is an argument: the procedure passes the stopwatch's
  measured value or the rig's nominal data-sheet value.

* **the platform rms net of the baseline's pickoff noise** (Ch. V E.2 less Ch. V B, Fig. 33):
  the same band integral of the survey's gyro PSD less the open-loop (clamped platform) PSD of
  the same pickoff, bin by bin, ``sqrt(max(0, integral (S_g - S_b) / Kg^2 df))``
  (``baseline_net_rms``): the pickoff noise the thesis method credits to the platform, taken
  out as the baseline measured it.

* PSDs (urad^2/Hz) of the four autocollimator and two gyro channels, and the coherences
  autocollimator control - gyro per axis (Figs. 44/47), X - Y control channels (Fig. 48) and
  X - Y gyro (Fig. 49), as App. A.8 plots (``COHERENCE_PAIRS``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
import scipy.ndimage
import scipy.signal
import scipy.stats

from daq.filespectra import RunCsd, run_csd_matrix
from daq.reader import RunFile
from daq.spectral import band_rms, coherence
from drivers.rig_datasheet import RigCalibration
from procedures.analysis.drift import coupling_terms
from procedures.analysis.intervals import LEVEL, Estimate, from_stderr, judged
from procedures.analysis.transfer import BlockCsd, jackknife_se, unbiased_coherence

AXES = ("X", "Y")


def ac_ctl(axis: str) -> str:
    return f"ac_{axis.lower()}_ctl"


def ac_inst(axis: str) -> str:
    return f"ac_{axis.lower()}_inst"


def gyro(axis: str) -> str:
    return f"gyro_{axis.lower()}"


#: the channels a survey records
CHANNELS = (
    tuple(ac_ctl(a) for a in AXES) + tuple(ac_inst(a) for a in AXES) + tuple(gyro(a) for a in AXES)
)
#: the coherences plotted and summarized: control - gyro per axis, X - Y control, X - Y gyro
COHERENCE_PAIRS = [
    (ac_ctl("X"), gyro("X")),
    (ac_ctl("Y"), gyro("Y")),
    (ac_ctl("X"), ac_ctl("Y")),
    (gyro("X"), gyro("Y")),
]


class SurveySettings(Protocol):
    """The parameters the numerics read (the procedure's ``SurveyParams`` has them)."""

    band_lo_hz: float
    band_hi_hz: float
    dip_lo_hz: float
    dip_hi_hz: float
    dip_smooth_hz: float
    mode: int


def loop_sensor(axis: str, mode: int) -> str:
    """The sensor the axis's loop closes on: the control channel in Mode 3, the pickoff in the
    gyro modes 4 and 5 (Fig. 27). Its spectrum has the dip: the loop's sensitivity has zeros at
    the open-loop platform poles, the bearing resonance."""
    return ac_ctl(axis) if mode == 3 else gyro(axis)


class SpanError(ValueError):
    """The recorded spans cannot be analysed: none could be read, or their sample rates differ."""


# ---------------------------------------------------------------------------- the dip
@dataclass(frozen=True)
class Dip:
    freq_hz: float
    depth_db: float  # prominence of the minimum in the smoothed dB spectrum
    bin_hz: float  # the smoothed spectrum's lowest bin (before the parabola)


def smoothed_db(f: np.ndarray, p: np.ndarray, smooth_hz: float) -> np.ndarray:
    """10 log10 of a PSD, averaged in dB over a running window of ``smooth_hz`` (ends held)."""
    df = float(f[1] - f[0])
    k = max(1, int(round(smooth_hz / df)))
    floor = np.finfo(float).tiny
    db = 10.0 * np.log10(np.maximum(np.asarray(p, float), floor))
    return scipy.ndimage.uniform_filter1d(db, k, mode="nearest") if k > 1 else db


def find_dip(
    f: np.ndarray, p: np.ndarray, lo_hz: float, hi_hz: float, smooth_hz: float
) -> Dip | None:
    """The most prominent notch of a PSD between ``lo_hz`` and ``hi_hz`` (module docstring);
    None when the smoothed spectrum has no local minimum there."""
    f = np.asarray(f, float)
    db = smoothed_db(f, p, smooth_hz)
    sel = np.flatnonzero((f >= lo_hz) & (f <= hi_hz))
    if sel.size < 3:
        return None
    minima, props = scipy.signal.find_peaks(-db[sel], prominence=0.0)
    if minima.size == 0:
        return None
    j = int(np.argmax(props["prominences"]))
    i = int(sel[minima[j]])
    depth = float(props["prominences"][j])
    # least-squares parabola through the smoothed dB within +-smooth_hz (at least the 3 nearest bins)
    df = float(f[1] - f[0])
    half = max(1, int(round(max(smooth_hz, df) / df)))
    a, b = max(sel[0], i - half), min(sel[-1], i + half)
    x = f[a : b + 1] - f[i]
    freq = float(f[i])
    if x.size >= 3:
        c2, c1, _ = np.polyfit(x, db[a : b + 1], 2)
        if c2 > 0:
            vertex = -c1 / (2 * c2)
            if abs(vertex) <= half * df:
                freq = float(f[i] + vertex)
    return Dip(freq, depth, float(f[i]))


# ---------------------------------------------------------------------------- the Welch matrix over spans
@dataclass
class SpanCsd:
    """The Welch matrix averaged over the segments of several spans."""

    f: np.ndarray
    S: np.ndarray
    channels: tuple[str, ...]
    fs: float
    nperseg: int
    nfft: int
    segments_used: int
    segments_total: int
    dof: float
    seconds: float
    notes: list[str]

    def psd(self, channel: str) -> np.ndarray:
        i = self.channels.index(channel)
        return self.S[:, i, i].real.copy()


def spans_csd(
    spans: Sequence[tuple[Path, int, int]], channels: Sequence[str], seg_s: float
) -> SpanCsd:
    """Welch cross-spectral matrix over the given file spans (segments never straddle two
    spans; a span shorter than a segment, or a file that is gone, is left out with a note).
    Raises ``SpanError`` if no span can be analysed or their sample rates differ."""
    notes: list[str] = []
    parts: list[RunCsd] = []
    seconds = 0.0
    for file, start, stop in spans:
        try:
            with RunFile(file) as rf:
                nperseg = int(round(seg_s * rf.rate_hz))
                n = max(0, min(stop, rf.n_samples) - start)
                if n < nperseg:
                    notes.append(
                        f"{Path(file).name} samples {start}..{stop}: shorter than one {seg_s:g} s segment, "
                        f"left out"
                    )
                    continue
                parts.append(run_csd_matrix(rf, channels, nperseg=nperseg, start=start, stop=stop))
                seconds += n / rf.rate_hz
        except (
            OSError,
            ValueError,
        ) as exc:  # RunFileError is an OSError: a resumed piece's file may be gone
            notes.append(f"{Path(file).name} samples {start}..{stop}: not read ({exc})")
    if not parts:
        raise SpanError(
            "survey: no recorded span could be analysed: "
            + "; ".join(notes or ["nothing recorded"])
        )
    fs = {p.fs for p in parts}
    if len(fs) != 1:
        raise SpanError(f"survey: the recorded spans have different sample rates {sorted(fs)} Hz")
    k = np.array([p.segments_used for p in parts], float)
    S = sum(p.S * kk for p, kk in zip(parts, k)) / k.sum()
    first = parts[0]
    return SpanCsd(
        first.f,
        S,
        tuple(channels),
        first.fs,
        first.nperseg,
        first.nfft,
        int(k.sum()),
        sum(p.segments_total for p in parts),
        float(sum(p.dof for p in parts)),
        seconds,
        notes,
    )


# ---------------------------------------------------------------------------- the survey's figures
@dataclass
class SurveySpectra:
    """What the survey measures from one Welch matrix (module docstring)."""

    f: np.ndarray
    psd_urad: dict[str, np.ndarray]  # per channel, urad^2/Hz
    coh: np.ndarray  # magnitude-squared coherence, (f, channel, channel)
    dips: dict[str, Dip | None]  # per axis, of the control channel
    platform_rms_urad: dict[str, float]  # per axis, gyro-deduced, band_lo_hz..band_hi_hz
    ac_ctl_rms_urad: dict[str, float]  # per axis, same band
    stiffness_Nm_per_rad: dict[str, float | None]  # per axis, I (2 pi f_dip)^2
    #: per pair of COHERENCE_PAIRS: (frequency, value) of the largest 1-Hz average in 1-30 Hz
    peak_coherence: dict[tuple[str, str], tuple[float, float]]


@dataclass(frozen=True)
class CrossCoherence:
    """The mean coherence of two channels over a band, against its distribution when they are
    independent (Fig. 48: a noise common to the X and Y autocollimators)."""

    pair: tuple[str, str]
    band_hz: tuple[float, float]
    mean: float
    null_mean: float
    z: float
    significant: bool

    def values(self) -> dict[str, object]:
        return {
            "pair": list(self.pair),
            "band_hz": list(self.band_hz),
            "mean": round(self.mean, 5),
            "null_mean": round(self.null_mean, 5),
            "z": round(self.z, 2),
            "significant": self.significant,
        }


#: z of the band-mean coherence above its null mean at which it is called significant (one-sided
#: p ~ 2e-4, so a survey of independent channels calls it in about one run of five thousand)
CROSS_Z = 3.5


def cross_axis_coherence(
    csd: SpanCsd, x: str, y: str, lo_hz: float = 1.0, hi_hz: float = 100.0
) -> CrossCoherence:
    """Mean magnitude-squared coherence of ``x`` and ``y`` over ``lo..hi`` Hz and its significance.

    For independent Gaussian channels the coherence of one bin averaged over n effectively
    independent segments is Beta(1, n - 1) (Bendat and Piersol), mean 1/n and variance
    (n - 1) / (n^2 (n + 1)); n is the Welch EDOF over 2. Adjacent Hann bins are correlated, so
    the band's mean counts half its bins as independent (conservative)."""
    f = csd.f
    hi_hz = min(hi_hz, 0.3 * csd.fs)
    band = (f >= lo_hz) & (f <= hi_hz)
    i, j = csd.channels.index(x), csd.channels.index(y)
    g = coherence(csd.S)[band, i, j]
    n = max(csd.dof / 2.0, 2.0)
    null_mean = 1.0 / n
    null_var = (n - 1) / (n * n * (n + 1))
    m = float(np.mean(g)) if g.size else float("nan")
    z = (m - null_mean) / math.sqrt(null_var / max(g.size / 2.0, 1.0)) if g.size else float("nan")
    return CrossCoherence((x, y), (lo_hz, hi_hz), m, null_mean, z, bool(z > CROSS_Z))


def platform_gyro(axis: str) -> str:
    """The X-Y gyro's reading of platform ``axis`` alone, in urad (``decoupled_gyro``)."""
    return f"gyro_{axis.lower()}_platform"


def decoupled_gyro(
    kg_V_per_urad: Mapping[str, float], h_over_c: Mapping[str, float], scale: float = 1.0
) -> dict[str, dict[str, float]]:
    """The weights (urad per volt) that combine the X-Y gyro's two pickoffs into a reading of
    each platform axis alone, ``{platform_gyro(axis): {pickoff: weight}}`` (II C.4.d).

    The float's viscous drag couples its two input axes: sigma_Y' = f_Y - (c/h)_X sigma_X' and
    sigma_X' = f_X + (c/h)_Y sigma_Y' (the simulator's plant, the thesis's float), so above the
    restraint's corner (1 / (h/k), ~2e-3 rad/s) the pickoffs read
    g_X = (theta_X + (c/h)_Y theta_Y) / (1 + (c/h)_X (c/h)_Y) and
    g_Y = (theta_Y - (c/h)_X theta_X) / (1 + (c/h)_X (c/h)_Y), whose inverse is
    theta_X = g_X - (c/h)_Y g_Y and theta_Y = g_Y + (c/h)_X g_X. With the data sheet's
    (c/h)_X = 1 / 1.96 the Y pickoff alone read the platform's Y rms up to 17 % high on drawn rigs
    (half the X motion in it). ``scale`` multiplies both c/h (the allowance's check)."""
    scaled = {a: v / scale for a, v in h_over_c.items()}
    out = {}
    for axis in ("X", "Y"):
        other, coupling = coupling_terms(axis, scaled)
        assert other is not None  # X and Y share the X-Y gyro's float
        out[platform_gyro(axis)] = {
            gyro(axis): 1.0 / kg_V_per_urad[axis],
            gyro(other): coupling / kg_V_per_urad[other],
        }
    return out


def with_coupling_allowance(
    nominal: Mapping[str, Estimate],
    at_scale: Callable[[float], Mapping[str, float]],
    tolerance: float,
) -> dict[str, Estimate]:
    """Each of ``nominal``'s figures (read with the data sheet's h/c) with the allowance for a
    unit's h/c anywhere in its tolerance: ``at_scale(s)`` the figures' values with both c/h
    multiplied by s (``decoupled_gyro``'s ``scale``), at s = 1 -+ ``tolerance``."""
    variants = [at_scale(1.0 + s) for s in (-tolerance, tolerance)]
    return {k: with_allowance(e, [v[k] for v in variants]) for k, e in nominal.items()}


def with_allowance(est: Estimate, variants: Sequence[float]) -> Estimate:
    """``est`` with its interval widened on each side by the largest departure of ``variants``
    (the same figure with a data-sheet constant at the ends of its tolerance) from its value."""
    if not est.resolved and not math.isfinite(est.value):
        return est
    d = max((abs(v - est.value) for v in variants if math.isfinite(v)), default=0.0)
    lo, hi = max(0.0, est.lo - d), est.hi + d
    if not est.resolved:
        return Estimate(est.value, lo, hi, False, est.why)
    return judged(est.value, lo, hi)


def coherent_platform_rms(
    blocks: BlockCsd,
    gyro_channel: str,
    ac_channels: str | Sequence[str],
    kg_V_per_urad: float,
    lo_hz: float,
    hi_hz: float,
) -> Estimate:
    """The platform's own rms (urad) in ``lo..hi`` Hz: the part of the gyro's spectrum coherent
    with the autocollimators, gamma_m^2 S_gg (the coherent output power, eq. 4.44-4.49; Ch. V C;
    with several inputs the multiple coherence, Bendat and Piersol ch. 7).

    The gyro sees theta + n_g, each autocollimator theta + n_a; the pickoff noise n_g is
    independent of them. In Mode 3 the platform moves because the loops follow the
    autocollimators' noise: theta = -T n_a on one axis, exactly recovered as |S_ga|^2 / S_aa =
    |T|^2 S_nn. But an axis also moves with the other's noise through the rig's cross-axis
    coupling (the gyro floats' reaction): that part is not coherent with its own autocollimator,
    and one input read the platform's rms up to 13 % low on a drawn rig. With every axis's
    autocollimator as an input, S_ga S_aa^-1 S_ag holds all the motion the loops make; a
    disturbance torque moves theta in both sensors and counts too. Nothing here needs the
    pickoff noise's level, or an open-loop baseline.

    gamma_m^2 is first freed of its bias over n averaged segments and q inputs,
    (n gamma^2 - q) / (n - q), n the Welch EDOF / 2 (with no coherence E[gamma_m^2] = q / n):
    with the pickoff noise ten times the platform's power the raw estimate read the rms 6-30 %
    high. The interval is a delete-one jackknife over the blocks (Student's t)."""
    inputs = [ac_channels] if isinstance(ac_channels, str) else list(ac_channels)
    f = blocks.f
    df = float(f[1] - f[0]) if len(f) > 1 else 1.0 / blocks.seg_s  # blocks may be a band already
    # the band's bins of the channels used, once: 1 + n_blocks means follow
    sub = blocks.subset([gyro_channel, *inputs], (f >= lo_hz) & (f <= hi_hz))
    g, a = 0, list(range(1, 1 + len(inputs)))

    def rms(leave_out: int | None) -> float:
        S = sub.mean(leave_out)
        sgg = S[:, g, g].real
        s_ga = S[:, g][:, a]  # (f, q): S_g,a
        S_aa = S[:, a][:, :, a]  # (f, q, q)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.linalg.solve(S_aa, s_ga.conj()[:, :, None])[:, :, 0]  # S_aa^-1 S_a,g
            g2 = np.einsum("fq,fq->f", s_ga, x).real / sgg
        g2u = unbiased_coherence(g2, blocks.averages(leave_out), inputs=len(a))
        return math.sqrt(float(np.sum(g2u * sgg)) * df) / kg_V_per_urad

    value = rms(None)
    loo = np.array([rms(b) for b in range(blocks.n_blocks)])
    return from_stderr(value, float(jackknife_se(loo)), dof=blocks.n_blocks - 1)


class BaselineMismatch(ValueError):
    """The baseline's spectrum cannot be set bin by bin against the survey's."""


@dataclass(frozen=True)
class BaselineNet:
    """The platform's rms net of the baseline's pickoff noise, and the two band rms it is made of."""

    estimate: Estimate  # urad; unresolved when the difference is not significantly above zero
    survey_rms_urad: (
        float  # the gyro's rms in the band in the survey (the thesis method on these blocks)
    )
    baseline_rms_urad: float  # the same pickoff's rms in the band with the platform clamped
    dof: float  # Welch-Satterthwaite degrees of freedom of the difference's interval


def baseline_net_rms(
    survey: BlockCsd,
    survey_channel: str,
    baseline: BlockCsd,
    baseline_channel: str,
    kg_V_per_urad: float,
    lo_hz: float,
    hi_hz: float,
) -> BaselineNet:
    """sqrt(max(0, integral over lo..hi Hz of (S_survey - S_baseline) / Kg^2 df)) in urad (Ch. V E.2
    with the open-loop pickoff spectrum of Ch. V B, Fig. 33, taken out bin by bin).

    The gyro reads theta + n_g in the survey and n_g alone with the platform clamped; with n_g
    stationary and independent of theta the band variances subtract. Each record's band variance
    is a mean over its blocks, so a delete-one jackknife over each record's blocks gives its
    standard error exactly as a linear statistic's; the two records are independent, so the
    difference's variance is the sum, its degrees of freedom Welch-Satterthwaite's. The 95 %
    interval of the variance maps to the rms through sqrt(max(0, .)) (monotone, so it covers as
    the variance's does). A difference whose lower bound is not above zero is reported
    unresolved, with the interval [0, sqrt(hi)]."""
    fs_, fb_ = survey.f, baseline.f
    bs = (fs_ >= lo_hz) & (fs_ <= hi_hz)
    bb = (fb_ >= lo_hz) & (fb_ <= hi_hz)
    if bs.sum() != bb.sum() or not np.allclose(fs_[bs], fb_[bb], rtol=0, atol=1e-9):
        raise BaselineMismatch(
            f"the baseline's Welch bins ({baseline.seg_s:g} s segments at {baseline.fs:g} Hz) "
            f"are not the survey's ({survey.seg_s:g} s at {survey.fs:g} Hz) in {lo_hz:g}-{hi_hz:g} Hz"
        )
    df = float(fs_[1] - fs_[0])
    k2 = kg_V_per_urad**2

    def variance(blocks: BlockCsd, channel: str, band: np.ndarray) -> tuple[float, float, int]:
        i = blocks.index(channel)

        def v(leave_out: int | None) -> float:
            return float(np.sum(blocks.mean(leave_out)[band, i, i].real)) * df / k2  # urad^2

        loo = np.array([v(b) for b in range(blocks.n_blocks)])
        return v(None), float(jackknife_se(loo)), blocks.n_blocks - 1

    vs, ses, ns = variance(survey, survey_channel, bs)
    vb, seb, nb = variance(baseline, baseline_channel, bb)
    d = vs - vb
    se2 = ses**2 + seb**2
    quart = ses**4 / ns + seb**4 / nb
    dof = se2**2 / quart if quart > 0 else float(ns + nb)
    q = float(scipy.stats.t.ppf(0.5 + LEVEL / 2, dof))
    lo, hi = d - q * math.sqrt(se2), d + q * math.sqrt(se2)
    value = math.sqrt(max(0.0, d))
    rms_hi = math.sqrt(max(0.0, hi))
    if not lo > 0:
        est = Estimate(
            value,
            0.0,
            rms_hi,
            False,
            f"the survey's gyro variance in the band ({vs:.4g} urad²) is not significantly above the "
            f"baseline's pickoff noise ({vb:.4g} urad²): difference {d:+.3g} +- {q * math.sqrt(se2):.3g}",
        )
    else:
        est = judged(value, math.sqrt(lo), rms_hi)
    return BaselineNet(est, math.sqrt(max(vs, 0.0)), math.sqrt(max(vb, 0.0)), dof)


def survey_spectra(
    csd: SpanCsd, cal: RigCalibration, kg_mV_per_urad: Mapping[str, float], p: SurveySettings
) -> SurveySpectra:
    """The PSDs in urad^2/Hz (the autocollimators' scales from the data sheet ``cal``, the
    pickoffs' ``kg_mV_per_urad``), the dips, the band rms values and the coherences."""
    f = csd.f
    kac = {a: cal.autocollimator[a].control_mV_per_urad * 1e-3 for a in AXES}  # V/urad
    kai = {a: cal.autocollimator[a].inst_mV_per_urad * 1e-3 for a in AXES}
    kg = {a: kg_mV_per_urad[a] * 1e-3 for a in AXES}
    scale = (
        {ac_ctl(a): kac[a] for a in AXES}
        | {ac_inst(a): kai[a] for a in AXES}
        | {gyro(a): kg[a] for a in AXES}
    )
    psd_urad = {c: csd.psd(c) / scale[c] ** 2 for c in csd.channels}  # urad^2/Hz
    coh = coherence(csd.S)

    dips = {
        a: find_dip(f, psd_urad[loop_sensor(a, p.mode)], p.dip_lo_hz, p.dip_hi_hz, p.dip_smooth_hz)
        for a in AXES
    }
    rms = {a: band_rms(f, psd_urad[gyro(a)], p.band_lo_hz, p.band_hi_hz) for a in AXES}
    ac_rms = {a: band_rms(f, psd_urad[ac_ctl(a)], p.band_lo_hz, p.band_hi_hz) for a in AXES}
    stiffness = {
        a: (
            cal.platform[a].inertia_kg_m2 * (2 * math.pi * d.freq_hz) ** 2
            if (d := dips[a]) is not None
            else None
        )
        for a in AXES
    }

    idx = {c: i for i, c in enumerate(csd.channels)}
    peak_coh = {}
    for x, y in COHERENCE_PAIRS:
        band = (f >= 1.0) & (f <= 30.0)
        smooth = scipy.ndimage.uniform_filter1d(
            coh[band, idx[x], idx[y]], max(1, int(round(1.0 / (f[1] - f[0]))))
        )
        k = int(np.argmax(smooth))
        peak_coh[(x, y)] = (float(f[band][k]), float(smooth[k]))
    return SurveySpectra(f, psd_urad, coh, dips, rms, ac_rms, stiffness, peak_coh)
