"""The drift numerics: per gyro channel, the Allan analysis of the torquing rate
``r = -K_TO V_T`` (urad/s) of a long Mode-3 record, pooled over the record's gap-free runs
(Allan terms never straddle a gap or a resume). Arrays and run files in, plain dataclasses
(``ChannelDrift``, ``LoopGain``) out; no rig. The procedure that records is
``procedures.calibrations.drift``; the report's text and plots are ``procedures.reports.drift``.

Per channel (``analyze_channels``):

* the overlapping Allan deviation with confidence intervals (``procedures.analysis.allan``, which
  wraps ``allantools``);
* the angle random walk N from the tau^-1/2 line through ``arw_tau_lo_s .. arw_tau_hi_s``
  (IEEE 952 Annex C), with the freely fitted slope as the check that it is a white-rate region;
* the caging loop's proportional gain G_p (torquing rate per pickoff angle, from the recorded
  pickoff and torquer channels above the loop's bandwidth) and the white rate N_loop the
  pickoff's output makes through it;
* the bias instability B = (flat minimum of the Allan deviation) / 0.664 (IEEE 952), read at
  tau >= ``bi_min_loop_tc`` loop time constants 1/G_p, where the torquer follows the drift;
* the null stability in the style of the thesis' Table 1 (peak-to-peak wander over 24 hours):
  the peak-to-peak of ``average_s`` means of r over the record, labelled with the record length,
  and an estimate for 24 hours from the Allan deviation when the record is shorter
  (``allan.null_stability``).

What the torquer output is not: the caging amplifier's proportional path passes the pickoff
noise to the torquer (above the loop's bandwidth the torquing rate is the proportional gain
times the pickoff noise angle), and the loop passes the platform's own motion about the input
axis (the optical stabilization's noise) below it. So the short-tau Allan deviation is the
white-rate level of the whole loop, an upper bound on the gyro's own random walk, not the
gyro's N alone; the bias-instability floor is the gyro's only where these have fallen away.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from daq.reader import RunFile
from drivers.calibration import GYRO_CHANNELS
from procedures.analysis import allan


def torq(ch: str) -> str:
    return f"torq_{ch.lower()}"


def pickoff(ch: str) -> str:
    return f"gyro_{ch.lower()}"


class DriftSettings(Protocol):
    """The parameters the numerics read (the procedure's ``DriftParams`` has them, with their meanings)."""

    arw_tau_lo_s: float
    arw_tau_hi_s: float
    bi_min_loop_tc: float
    loop_band_lo_hz: float
    loop_band_hi_frac: float
    min_edf: float
    average_s: float
    null_span_s: float


class DriftDataError(ValueError):
    """The record cannot be analysed: a channel has no gap-free data, or the files' sample rates differ."""


def load_record(spans: Iterable[tuple[str | Path, int, int]], names: list[str], default_rate_hz: float
                ) -> tuple[dict[str, list[np.ndarray]], int, int, float]:
    """Raw volts of the channels ``names`` per continuous stretch ((file, start, stop) samples;
    NaN where lost), samples, samples lost, and the sample rate (``default_rate_hz`` if no span)."""
    chunks: dict[str, list[np.ndarray]] = {n: [] for n in names}
    total = lost = 0
    rate = None
    for file, start, stop in spans:
        with RunFile(file) as rf:
            if rate is not None and rf.rate_hz != rate:
                raise DriftDataError(f"{file} was recorded at {rf.rate_hz:g} Hz, the others at {rate:g} Hz")
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
    mean_rate: float                          # urad/s (earth rate + drift)
    adev: allan.AllanResult
    arw: allan.ArwReadoff | None
    bi: allan.BiasInstabilityReadoff | None
    null: allan.NullStability | None
    problems: list[str]
    loop: LoopGain | None = None
    bi_min_tau_s: float = 0.0


@dataclass
class LoopGain:
    """The caging loop's proportional gain, seen in the record: above the loop's bandwidth the
    torquing rate r = -K_TO V_T is G_p times the pickoff angle a = V_g / K_g (the amplifier is
    a filter of the pickoff voltage), so G_p = |S_ar / S_aa| there (H1). The pickoff's noise
    in that band, through G_p, is the torquer's white rate: N_loop = G_p sqrt(S_aa / 2)."""

    gain_per_s: float            # G_p (urad/s per urad)
    pickoff_asd: float           # sqrt(S_aa) in the band, urad/sqrt(Hz)
    coherence: float             # mean magnitude-squared coherence in the band
    band_hz: tuple[float, float]

    @property
    def time_constant_s(self) -> float:
        return 1.0 / self.gain_per_s

    @property
    def white_rate(self) -> float:
        """N_loop (urad/sqrt(s)) the pickoff noise makes through the proportional path."""
        return self.gain_per_s * self.pickoff_asd / math.sqrt(2.0)


def measure_loop_gain(torq_segs: list[np.ndarray], pick_segs: list[np.ndarray], rate_hz: float,
                      band_hz: tuple[float, float], max_samples: int = 2 ** 17) -> LoopGain | None:
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
    return LoopGain(float(np.median(np.abs(h))), float(np.sqrt(np.mean(s_aa[sel]))), float(np.mean(coh)),
                    (float(f[sel][0]), float(f[sel][-1])))


def analyze_channels(chunks: dict[str, list[np.ndarray]], rate_hz: float, kto: dict[str, float],
                     p: DriftSettings, kg_mV_per_urad: dict[str, float] | None = None) -> dict[str, ChannelDrift]:
    """Per channel: rate r = -K_TO V (urad/s) split at gaps, its Allan deviation and read-offs.
    With the pickoff chunks and ``kg_mV_per_urad`` the loop gain is measured as well and the
    bias instability is read beyond ``p.bi_min_loop_tc`` loop time constants; without, beyond
    the ARW range."""
    out = {}
    band = (p.loop_band_lo_hz, p.loop_band_hi_frac * rate_hz)
    for ch in GYRO_CHANNELS:
        volts = chunks[torq(ch)]
        segs = [s for c in volts for s in allan.split_finite(-kto[ch] * c)]
        if not segs:
            raise DriftDataError(f"channel {ch}: no gap-free data in the record")
        mean = float(np.average([s.mean() for s in segs], weights=[len(s) for s in segs]))
        res = allan.allan_deviation(segs, rate_hz)
        problems: list[str] = []
        loop = None
        if kg_mV_per_urad is not None and pickoff(ch) in chunks:
            # the same gap-free stretches of both channels (a lost sample set is lost on all)
            both = [np.vstack([-kto[ch] * t, 1e3 * g / kg_mV_per_urad[ch]])
                    for t, g in zip(volts, chunks[pickoff(ch)])]
            runs = [b[:, a:z] for b in both for a, z in _finite_runs(np.asarray(np.isfinite(b).all(axis=0)))]
            loop = measure_loop_gain([b[0] for b in runs], [b[1] for b in runs], rate_hz, band)
            if loop is None:
                problems.append("loop gain: record too short for a spectrum in the band; bias instability "
                                "read beyond the ARW range instead")
        bi_min_tau = p.bi_min_loop_tc * loop.time_constant_s if loop else p.arw_tau_hi_s
        arw = bi = null = None
        try:
            arw = allan.read_arw(res, (p.arw_tau_lo_s, p.arw_tau_hi_s), min_edf=p.min_edf)
        except ValueError as exc:
            problems.append(f"ARW: {exc}")
        try:
            bi = allan.read_bias_instability(res, min_edf=p.min_edf, min_tau_s=bi_min_tau)
        except ValueError as exc:
            problems.append(f"bias instability: {exc}")
        try:
            null = allan.null_stability(segs, rate_hz, res, avg_s=p.average_s, span_s=p.null_span_s,
                                        min_edf=p.min_edf)
        except ValueError as exc:
            problems.append(f"null stability: {exc}")
        out[ch] = ChannelDrift(ch, kto[ch], mean, res, arw, bi, null, problems, loop, bi_min_tau)
    return out


def _finite_runs(ok: np.ndarray) -> list[tuple[int, int]]:
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


def pickoff_stats(chunks: dict[str, list[np.ndarray]], kg_mV_per_urad: dict[str, float]) -> dict[str, tuple[float, float]]:
    """Per channel, the pickoff angle's mean and rms about it (urad) over the record's valid samples:
    the check that the loops held the pickoffs at null."""
    out = {}
    for ch in GYRO_CHANNELS:
        v = np.concatenate(chunks[pickoff(ch)])
        v = v[np.isfinite(v)] * 1e3 / kg_mV_per_urad[ch]
        out[ch] = (float(v.mean()), float(v.std())) if len(v) else (math.nan, math.nan)
    return out
