"""The drift numerics: per gyro channel, the gyro's input rate reconstructed from a long Mode-3
record of the torquer and pickoff outputs, and its Allan analysis, pooled over the record's
gap-free runs (Allan terms never straddle a gap or a resume). Arrays and run files in, plain
dataclasses (``ChannelDrift``, ``LoopGain``) out; no rig. The procedure that records is
``procedures.calibrations.drift``; the report's text and plots are ``procedures.reports.drift``;
docs/procedures/drift.md has the method and what was measured.

Per channel (``analyze_channels``):

* the input rate Omega_in = sigma' + sigma / (h/k) - K_TO V_T from the float's equation of motion
  (thesis II C.1.a(8), III A; ``reconstruct_rate``): the caging loop's transfer cancels, the
  pickoff's measurement noise remains, as n' + n / (h/k);
* its overlapping Allan deviation with confidence intervals (``procedures.analysis.allan``, which
  wraps ``allantools``);
* the IEEE 952 terms fitted to it (``allan.fit_noise_model``) and, from them, the angle random
  walk N and the bias instability B, each with a 95 % interval for the gyro's parameter or, where
  the record cannot tell it from the other terms, only the bound the data support
  (``allan.term_estimate``; ``ChannelDrift.estimate`` judges them by the rule of
  ``procedures.analysis.intervals``);
* the caging loop's proportional gain G_p (torquing rate per pickoff angle above the loop's
  bandwidth) and the white rate N_loop the pickoff's noise makes through it: what the torquer
  output alone shows at short tau, a diagnostic, not the gyro's N;
* the null stability in the style of the thesis' Table 1 (peak-to-peak wander over 24 hours):
  the peak-to-peak of ``average_s`` means of the input rate over the record, labelled with the
  record length, and an estimate for 24 hours from the Allan deviation when the record is
  shorter (``allan.null_stability``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from daq.reader import RunFile
from drivers.rig_datasheet import GYRO_CHANNELS, GYRO_PAIRS
from procedures.analysis import allan
from procedures.analysis.intervals import Estimate, judged


def torq(ch: str) -> str:
    return f"torq_{ch.lower()}"


def pickoff(ch: str) -> str:
    return f"gyro_{ch.lower()}"


#: a term is resolved only where it holds at least this share of the modelled Allan variance at
#: the averaging time it is read (IEEE Std 952: a term is read where it dominates). Below it the
#: fitted model's shapes, not the data, apportion the variance: over 50 default sim runs (N 0.005
#: under 0.6 urad of pickoff noise) 3 of 200 channels had N "resolved" at 20-40x the truth with
#: shares of 25-41 %, while the true N of 0.3 was read at 56-92 % and B at 60-88 %
#: (``bench/drift_coverage.py``)
MIN_SHARE_TO_RESOLVE = 0.5


class DriftSettings(Protocol):
    """The parameters the numerics read (the procedure's ``DriftParams`` has them, with their meanings)."""

    fit_tau_lo_s: float
    loop_band_lo_hz: float
    loop_band_hi_frac: float
    min_edf: float
    average_s: float
    null_span_s: float


class DriftDataError(ValueError):
    """The record cannot be analysed: a channel has no gap-free data, or the files' sample rates differ."""


def load_record(
    spans: Iterable[tuple[str | Path, int, int]], names: list[str], default_rate_hz: float
) -> tuple[dict[str, list[np.ndarray]], int, int, float]:
    """Raw volts of the channels ``names`` per continuous stretch ((file, start, stop) samples;
    NaN where lost), samples, samples lost, and the sample rate (``default_rate_hz`` if no span)."""
    chunks: dict[str, list[np.ndarray]] = {n: [] for n in names}
    total = lost = 0
    rate = None
    for file, start, stop in spans:
        with RunFile(file) as rf:
            if rate is not None and rf.rate_hz != rate:
                raise DriftDataError(
                    f"{file} was recorded at {rf.rate_hz:g} Hz, the others at {rate:g} Hz"
                )
            rate = rf.rate_hz
            data = rf.read(names, start, stop)
        for n, row in zip(names, data):
            chunks[n].append(row)
        total += data.shape[1]
        lost += int(np.count_nonzero(~np.isfinite(data).all(axis=0)))
    return chunks, total, lost, float(rate or default_rate_hz)


@dataclass
class ChannelDrift:
    channel: str
    kto: float
    mean_rate: float  # urad/s (earth rate + drift)
    adev: allan.AllanResult  # of the reconstructed input rate
    model: allan.NoiseModel | None  # IEEE 952 terms fitted to it
    arw: allan.TermEstimate | None  # N (urad/sqrt(s)) with its 95 % interval
    bi: allan.TermEstimate | None  # B (urad/s) with its 95 % interval
    null: allan.NullStability | None
    problems: list[str]
    loop: LoopGain | None = None
    adev_torquer: allan.AllanResult | None = None  # of -K_TO V_T alone (the loop's output)
    #: how far the K_TO and K_g used may lie from the unit's (relative, 95 %): 0 for a measured
    #: scale (earth-rate, stopwatch), the data sheet's tolerance for a nominal one
    scale_tol: tuple[float, float] = (0.0, 0.0)

    def figure_tolerance(self, term: str) -> float:
        """The relative error of figure ``term`` the scales' tolerance allows: the reconstructed rate
        is r + sigma' + sigma / (h/k) with r proportional to K_TO and sigma to 1 / K_g, so a figure
        read where r carries the input rate (B, at taus beyond the caging loop's time constant)
        scales as K_TO, and N, read where either may carry it, by a blend of the two scale errors,
        which lies between them."""
        kto, kg = self.scale_tol
        return kto if term == "bias" else max(kto, kg)

    def estimate(self, term: str) -> Estimate:
        """The figure ``term`` ("arw" or "bias") as a reported estimate: resolved by the
        intervals rule (``procedures.analysis.intervals.judged``) when the data show it and it
        dominates where it is read (``MIN_SHARE_TO_RESOLVE``), else unresolved with 0 .. its
        one-sided 95 % upper limit (``allan.TermEstimate.upper``). Where the scales used
        are nominal (``scale_tol``), the interval is widened by their tolerance: the truth is the
        figure times K_unit / K_used (``figure_tolerance``), so lo (1 - t) .. hi (1 + t)."""
        e = self._estimate(term)
        t = self.figure_tolerance(term)
        if t <= 0 or not (math.isfinite(e.lo) and math.isfinite(e.hi)):
            return e
        lo, hi = e.lo * (1.0 - t), e.hi * (1.0 + t)
        if not e.resolved:
            return Estimate(e.value, lo, hi, False, e.why)
        w = judged(e.value, lo, hi)
        # widened past resolving: unresolved as ``_estimate`` makes it, 0 .. the upper limit
        return w if w.resolved else Estimate(e.value, 0.0, hi, False, w.why)

    def _estimate(self, term: str) -> Estimate:
        t = self.arw if term == "arw" else self.bi
        if t is None:
            return Estimate(
                math.nan, math.nan, math.nan, False, "; ".join(self.problems) or "not measured"
            )
        if not math.isfinite(t.value):
            return Estimate(math.nan, t.lo, t.hi, False, t.why)
        if t.share < MIN_SHARE_TO_RESOLVE:
            # the model's apportioning is no evidence of the term: 0 .. its one-sided limit, or
            # where it has none the model-free bound
            return Estimate(
                t.value,
                0.0,
                t.upper if math.isfinite(t.upper) else max(t.bound, t.hi),
                False,
                f"it holds only {100 * t.share:.0f} % of the modelled Allan variance where it is read "
                f"(tau {t.tau_s:g} s): the model's shapes, not the data, apportion it",
            )
        e = judged(t.value, t.lo, t.hi)
        if not e.resolved:
            # unresolved: only the upper limit is the data's; the lower one is the measured variance
            # less the other terms' modelled share, and where the term does not stand clear of them
            # the model's split decides it (issue 38: B [0.025, 0.081] for a true 0.019 under a large
            # N, whose white rate the fit had given B at the long taus)
            return Estimate(t.value, 0.0, t.upper_limit, False, e.why)
        return e


@dataclass
class LoopGain:
    """The caging loop's proportional gain, seen in the record: above the loop's bandwidth the
    torquing rate r = -K_TO V_T is G_p times the pickoff angle a = V_g / K_g (the amplifier is
    a filter of the pickoff voltage), so G_p = |S_ar / S_aa| there (H1). The pickoff's noise
    in that band, through G_p, is the torquer's white rate: N_loop = G_p sqrt(S_aa / 2)."""

    gain_per_s: float  # G_p (urad/s per urad)
    pickoff_asd: float  # sqrt(S_aa) in the band, urad/sqrt(Hz)
    coherence: float  # mean magnitude-squared coherence in the band
    band_hz: tuple[float, float]

    @property
    def time_constant_s(self) -> float:
        return 1.0 / self.gain_per_s

    @property
    def white_rate(self) -> float:
        """N_loop (urad/sqrt(s)) the pickoff noise makes through the proportional path."""
        return self.gain_per_s * self.pickoff_asd / math.sqrt(2.0)


def measure_loop_gain(
    torq_segs: list[np.ndarray],
    pick_segs: list[np.ndarray],
    rate_hz: float,
    band_hz: tuple[float, float],
    max_samples: int = 2**17,
) -> LoopGain | None:
    """G_p from the longest common gap-free stretch (rate r, pickoff angle a); None if the
    stretch is too short for a spectrum resolving the band."""
    from scipy.signal import csd, welch

    pairs = [(r, a) for r, a in zip(torq_segs, pick_segs) if len(r) == len(a)]
    if not pairs:
        return None
    r, a = max(pairs, key=lambda ra: len(ra[0]))
    r, a = r[:max_samples], a[:max_samples]
    nper = 1
    while nper * 2 <= len(r) // 8 and rate_hz / (nper * 2) >= band_hz[0] / 10:
        nper *= 2
    f = np.fft.rfftfreq(nper, 1 / rate_hz)
    sel = (f >= band_hz[0]) & (f <= band_hz[1])
    if nper < 64 or sel.sum() < 3:
        return None
    _, s_aa = welch(a, rate_hz, nperseg=nper)
    _, s_rr = welch(r, rate_hz, nperseg=nper)
    _, s_ar = csd(a, r, rate_hz, nperseg=nper)
    h = s_ar[sel] / s_aa[sel]
    coh = np.abs(s_ar[sel]) ** 2 / (s_aa[sel] * s_rr[sel])
    return LoopGain(
        float(np.median(np.abs(h))),
        float(np.sqrt(np.mean(s_aa[sel]))),
        float(np.mean(coh)),
        (float(f[sel][0]), float(f[sel][-1])),
    )


def reconstruct_rate(
    r: np.ndarray,
    a: np.ndarray,
    rate_hz: float,
    restraint_s: float,
    a_other: np.ndarray | None = None,
    coupling: float = 0.0,
) -> np.ndarray:
    """The gyro's input rate (urad/s) from one gap-free stretch of the torquing rate
    ``r = -K_TO V_T`` (urad/s) and the pickoff angle ``a = V_g / K_g`` (urad), through the
    float's equation of motion (thesis II C.1.a(8) and III A, below the nutation; docs/simhw.md
    section 3):

        sigma' = Omega_in + K_TO V_T - sigma / (h/k)      (before cross-axis coupling)
        =>  Omega_in = sigma' + sigma / (h/k) + r

    With the viscous cross-axis coupling (II C.4.d) the left side is the channel's own float
    rate plus ``coupling`` times the other input axis' (for (a, b, spin) right-handed,
    f_a = sigma_a' - (c_b/h) sigma_b' and f_b = sigma_b' + (c_a/h) sigma_a', the inverse of the
    coupled float equations): pass the other channel's pickoff angle ``a_other`` and the signed
    coefficient (-c_b/h for a, +c_a/h for b).

    Computed in angle ("phase") form, x(t) = a(t) + coupling a_other(t) + integral of
    (r + a / (h/k)) (trapezoid rule), and returned as the rate between samples, diff(x) fs: one
    sample shorter than the input. Both channels pass the same anti-alias filter, which
    commutes with this linear reconstruction, so the result is the filtered input rate. What
    it adds is the pickoff's measurement noise n as n' + n / (h/k): the caging loop does not
    enter (its transfer cancels), but the differentiated pickoff noise is, referred to the
    input, exactly what the loop had (below its bandwidth the torquer already is this sum)."""
    integrand = r + a / restraint_s
    x = a + (coupling * a_other if a_other is not None else 0.0)
    return np.diff(x) * rate_hz + 0.5 * (integrand[1:] + integrand[:-1])


def coupling_terms(channel: str, h_over_c: Mapping[str, float] | None) -> tuple[str | None, float]:
    """The other input axis of ``channel``'s gyro and the signed coupling coefficient of its
    float rate in ``reconstruct_rate`` (0 without the rig's h/c): sigma_a' = f_a + (c/h)_b sigma_b'
    and sigma_b' = f_b - (c/h)_a sigma_a' (II C.4.d; the simulator's plant); the same signs undo
    the coupling in the pickoffs (``procedures.analysis.survey.decoupled_gyro``)."""
    for a_ch, b_ch in GYRO_PAIRS:
        if h_over_c is None:
            break
        if channel == a_ch:
            return b_ch, -1.0 / h_over_c[b_ch]
        if channel == b_ch:
            return a_ch, 1.0 / h_over_c[a_ch]
    return None, 0.0


def analyze_channels(
    chunks: dict[str, list[np.ndarray]],
    rate_hz: float,
    kto: dict[str, float],
    p: DriftSettings,
    kg_mV_per_urad: dict[str, float],
    restraint_s: dict[str, float],
    h_over_c: dict[str, float] | None = None,
    *,
    scale_tol: Mapping[str, tuple[float, float]] | None = None,
) -> dict[str, ChannelDrift]:
    """Per channel: the input rate reconstructed from the torquer and pickoff outputs
    (``reconstruct_rate``) split at gaps, its Allan deviation, the IEEE 952 noise model fitted to
    it and the terms read with their intervals (``allan.term_estimate``), the null stability,
    and the caging loop's gain (a diagnostic: the loop's white rate, which the torquer output
    alone would show). ``scale_tol``: per channel the relative tolerance (95 %) of the K_TO and
    K_g given, where they are nominal (``ChannelDrift.scale_tol``)."""
    out = {}
    band = (p.loop_band_lo_hz, p.loop_band_hi_frac * rate_hz)
    for ch in GYRO_CHANNELS:
        other, coupling = coupling_terms(ch, h_over_c)
        rows = [-kto[ch] * chunks[torq(ch)][k] for k in range(len(chunks[torq(ch)]))]
        angle = [1e3 * g / kg_mV_per_urad[ch] for g in chunks[pickoff(ch)]]
        angle_other = (
            [1e3 * g / kg_mV_per_urad[other] for g in chunks[pickoff(other)]]
            if other
            else [np.zeros_like(g) for g in angle]
        )
        # the same gap-free stretches of all channels used (a lost sample set is lost on all)
        both = [np.vstack([t, g, o]) for t, g, o in zip(rows, angle, angle_other)]
        runs = [
            b[:, lo:hi]
            for b in both
            for lo, hi in _finite_runs(np.asarray(np.isfinite(b).all(axis=0)))
            if hi - lo >= 4
        ]
        if not runs:
            raise DriftDataError(f"channel {ch}: no gap-free data in the record")
        segs = [
            reconstruct_rate(
                b[0], b[1], rate_hz, restraint_s[ch], b[2] if other else None, coupling
            )
            for b in runs
        ]
        mean = float(np.average([s.mean() for s in segs], weights=[len(s) for s in segs]))
        res = allan.allan_deviation(segs, rate_hz)
        torq_res = allan.allan_deviation([b[0] for b in runs], rate_hz)
        problems: list[str] = []
        loop = measure_loop_gain([b[0] for b in runs], [b[1] for b in runs], rate_hz, band)
        if loop is None:
            problems.append("loop gain: record too short for a spectrum in the band")
        model = arw = bi = null = None
        try:
            model = allan.fit_noise_model(res, min_tau_s=p.fit_tau_lo_s)
        except ValueError as exc:
            problems.append(f"noise model: {exc}")
        if model is not None:
            for term in ("arw", "bias"):
                try:
                    est = allan.term_estimate(
                        res, model, term, min_edf=p.min_edf, min_tau_s=p.fit_tau_lo_s
                    )
                except ValueError as exc:
                    problems.append(f"{'ARW' if term == 'arw' else 'bias instability'}: {exc}")
                    continue
                if term == "arw":
                    arw = est
                else:
                    bi = est
        try:
            null = allan.null_stability(
                segs, rate_hz, res, avg_s=p.average_s, span_s=p.null_span_s, min_edf=p.min_edf
            )
        except ValueError as exc:
            problems.append(f"null stability: {exc}")
        out[ch] = ChannelDrift(
            ch,
            kto[ch],
            mean,
            res,
            model,
            arw,
            bi,
            null,
            problems,
            loop,
            torq_res,
            (scale_tol or {}).get(ch, (0.0, 0.0)),
        )
    return out


def _finite_runs(ok: np.ndarray) -> list[tuple[int, int]]:
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


def pickoff_stats(
    chunks: dict[str, list[np.ndarray]], kg_mV_per_urad: dict[str, float]
) -> dict[str, tuple[float, float]]:
    """Per channel, the pickoff angle's mean and rms about it (urad) over the record's valid samples:
    the check that the loops held the pickoffs at null."""
    out = {}
    for ch in GYRO_CHANNELS:
        v = np.concatenate(chunks[pickoff(ch)])
        v = v[np.isfinite(v)] * 1e3 / kg_mV_per_urad[ch]
        out[ch] = (float(v.mean()), float(v.std())) if len(v) else (math.nan, math.nan)
    return out
