"""``drift``: gyro drift stability from a long Mode-3 record of the torquer outputs.

In Mode 3 the caging loops hold every pickoff at null, so each channel's torquer output
cancels the rate about its input axis (II C.1.a(8)):

    r(t) = -K_TO V_T(t) = Omega_i + d(t)          (urad/s; earth rate + drift)

The earth-rate component is constant on a fixed table, so the wander of ``r`` is the drift's
(plus what the loop adds, below). Per channel the procedure computes

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

K_TO is a scale only: an earlier ``earth-rate`` result is used when the procedure is given
one (``prior``), else the rig's nominal data-sheet value, which the report says.

Steps: Mode 3 and a settle (setup, run again on ``--resume``), then the record in
``n_chunks`` data steps, each returning its file and time span, so an aborted overnight record
resumes where it stopped; the analysis pools the chunks' gap-free runs (Allan terms never
straddle a gap or a resume).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from daq.reader import RunFile
from drivers.calibration import GYRO_CHANNELS
from procedures.analysis import allan
from procedures.params import prior_value
from procedures.reports.plotting import new_figure, save_figure
from procedures.rigsetup import bring_to_mode3, wait_settled
from procedures.runner import Analysis, Context, Figure, Measurement, Procedure, ProcedureError, Span, Step

log = logging.getLogger(__name__)

#: the ADC's anti-alias filter is 3-pole at 0.3 fs (DESIGN.md section 5): the first few
#: samples' Allan deviation is shaped by it, so the white-rate fit starts at this many samples
MIN_ARW_SAMPLES = 2.0


@dataclass
class DriftParams:
    #: record length (rig seconds) after the settle
    duration_s: float = 7200.0
    rate_hz: float = 10.0
    #: the record is split into this many data steps (each resumable)
    n_chunks: int = 10
    #: settle: the torquing rate changes by less than this over ``settle_window_s`` (urad/s)
    settle_tol_urad_per_s: float = 0.02
    settle_window_s: float = 40.0
    settle_min_s: float = 120.0
    settle_timeout_s: float = 900.0
    #: the tau^-1/2 (white-rate) fit range for the angle random walk (s)
    arw_tau_lo_s: float = 0.4
    arw_tau_hi_s: float = 1.6
    #: the bias instability is read at tau >= this many caging-loop time constants 1/G_p, G_p the
    #: loop's proportional gain (torquing rate per pickoff angle) measured from the record: the
    #: torquer follows the drift only below the loop's bandwidth, and a PI loop's overshoot lifts
    #: the flicker's Allan deviation above its floor for a while beyond it (docs/procedures/drift.md)
    bi_min_loop_tc: float = 10.0
    #: band (Hz) where G_p is measured, well above the loop's bandwidth: from loop_band_lo_hz to
    #: loop_band_hi_frac x the sample rate (both channels pass the same anti-alias filter)
    loop_band_lo_hz: float = 0.2
    loop_band_hi_frac: float = 0.2
    #: Allan points with fewer equivalent degrees of freedom are not used for the read-offs
    #: (for the bias instability: Greenhall's EDF for flicker rate noise, allan.read_bias_instability)
    min_edf: float = 10.0
    #: null stability: the means averaged over this long, and the span the estimate is for
    average_s: float = 100.0
    null_span_s: float = 86400.0
    #: quality limits: the record must cover this much, and lose at most this fraction of samples
    min_record_s: float = 300.0
    max_lost_fraction: float = 0.01

    def __post_init__(self) -> None:
        if not self.duration_s > 0 or not self.rate_hz > 0:
            raise ValueError("drift: duration_s and rate_hz must be > 0")
        if not 1 <= int(self.n_chunks) <= 1000:
            raise ValueError(f"drift: n_chunks = {self.n_chunks} must be 1..1000")
        if not 0 < self.arw_tau_lo_s < self.arw_tau_hi_s:
            raise ValueError(f"drift: ARW fit range {self.arw_tau_lo_s}..{self.arw_tau_hi_s} s is empty")
        if self.arw_tau_lo_s * self.rate_hz < MIN_ARW_SAMPLES - 1e-9:
            raise ValueError(f"drift: the ARW fit starts at {self.arw_tau_lo_s:g} s = "
                             f"{self.arw_tau_lo_s * self.rate_hz:g} samples at {self.rate_hz:g} Hz; it must start at "
                             f">= {MIN_ARW_SAMPLES:g} samples (the anti-alias filter shapes shorter averages)")
        if not 0 < self.loop_band_lo_hz < self.loop_band_hi_frac * self.rate_hz <= 0.5 * self.rate_hz:
            raise ValueError(f"drift: loop-gain band {self.loop_band_lo_hz:g} .. "
                             f"{self.loop_band_hi_frac * self.rate_hz:g} Hz is empty or beyond Nyquist")
        if self.bi_min_loop_tc < 0:
            raise ValueError("drift: bi_min_loop_tc must be >= 0")
        if not self.average_s > 0 or not self.null_span_s >= self.average_s:
            raise ValueError("drift: need 0 < average_s <= null_span_s")


def _torq(ch: str) -> str:
    return f"torq_{ch.lower()}"


def _pickoff(ch: str) -> str:
    return f"gyro_{ch.lower()}"


def _hours(seconds: float) -> str:
    return f"{seconds / 3600:.3g} h" if seconds >= 3600 else f"{seconds:.4g} s"


#: the name the module's functions and tests use
Params = DriftParams


class Drift(Procedure[DriftParams]):
    name = "drift"
    title = "Gyro drift stability: Allan deviation of the caged torquer outputs (Mode 3)"
    json_keys = ("bias_instability_urad_per_s", "arw_urad_per_sqrt_s", "file")
    Params = DriftParams
    mode = 3
    block_s = 1.0

    def __init__(self, params: DriftParams | None = None, **kw) -> None:
        super().__init__(params, **kw)
        self.rate_hz = float(self.params.rate_hz)

    def channels(self) -> tuple[str, ...]:
        # the pickoffs ride along as the check that the loops held them at null
        return tuple(_torq(c) for c in GYRO_CHANNELS) + tuple(_pickoff(c) for c in GYRO_CHANNELS)

    def chunk_names(self) -> list[str]:
        n = int(self.params.n_chunks)
        return [f"record {i + 1}/{n}" for i in range(n)]

    def plan(self) -> list[Step]:
        p = self.params
        chunk_s = p.duration_s / int(p.n_chunks)
        return [Step("mode 3", bring_to_mode3, expected_s=300.0, setup=True),
                Step("settle", self.settle, expected_s=max(p.settle_min_s, p.settle_window_s) + 20.0, setup=True),
                *(Step(name, partial(self.record, seconds=chunk_s), expected_s=chunk_s)
                  for name in self.chunk_names())]

    # ------------------------------------------------------------------ steps
    def kto(self, ctx: Context) -> tuple[dict[str, float], str]:
        """K_TO per channel (urad/s/V) and where it came from."""
        nominal = ctx.rig.calibration.torquer_scale_urad_per_s_per_V
        got = {ch: prior_value(self.prior, "earth-rate", "K_TO_urad_per_s_per_V", ch, nominal[ch])
               for ch in GYRO_CHANNELS}
        out = {ch: v for ch, (v, _) in got.items()}
        used_nominal = [ch for ch, (_, src) in got.items() if src == "nominal"]
        if not used_nominal:
            source = "earth-rate result (prior run)"
        elif len(used_nominal) == len(GYRO_CHANNELS):
            source = "NOMINAL data-sheet values (no earth-rate result given)"
        else:
            source = f"earth-rate result; NOMINAL data-sheet value for {', '.join(used_nominal)}"
        return out, source

    def settle(self, ctx: Context) -> dict:
        p = self.params
        kto, _ = self.kto(ctx)
        cols = [ctx.column(_torq(c)) for c in GYRO_CHANNELS]
        tol_V = np.array([p.settle_tol_urad_per_s / abs(kto[c]) for c in GYRO_CHANNELS])
        s = wait_settled(ctx, cols, tol_V=tol_V, window_s=p.settle_window_s, min_s=p.settle_min_s,
                         timeout_s=p.settle_timeout_s)
        return {"waited_s": round(s.waited_s, 1)}

    def record(self, ctx: Context, seconds: float) -> dict:
        ctx.acquire(seconds, keep=False)   # where the samples are is the runner's record (ctx.spans)
        return {"seconds": seconds}

    # ------------------------------------------------------------------ analysis
    def load(self, spans: list[Span]) -> tuple[dict[str, list[np.ndarray]], int, int, float]:
        """Raw volts of every recorded channel per continuous stretch (NaN where lost),
        samples, samples lost, and the sample rate."""
        names = list(self.channels())
        chunks: dict[str, list[np.ndarray]] = {n: [] for n in names}
        total = lost = 0
        rate = None
        for span in spans:
            with RunFile(span.file) as rf:
                if rate is not None and rf.rate_hz != rate:
                    raise ProcedureError(f"{span.file} was recorded at {rf.rate_hz:g} Hz, the others at {rate:g} Hz")
                rate = rf.rate_hz
                data = rf.read(names, span.start, span.stop)
            for n, row in zip(names, data):
                chunks[n].append(row)
            total += data.shape[1]
            lost += int(np.count_nonzero(~np.isfinite(data).all(axis=0)))
        return chunks, total, lost, float(rate or self.rate_hz)

    def analyze(self, ctx: Context) -> Analysis:
        p = self.params
        spans = ctx.data_spans(self.chunk_names())
        if not spans:
            raise ProcedureError("no record step was done: nothing to analyse")
        kto, kto_source = self.kto(ctx)
        chunks, total, lost, rate = self.load(spans)
        record_s = total / rate
        cal = ctx.rig.calibration
        got_kg = {ch: prior_value(self.prior, "stopwatch", "K_g_mV_per_urad", ch, cal.pickoff_scale_mV_per_urad[ch])
                  for ch in GYRO_CHANNELS}
        kg = {ch: v for ch, (v, _) in got_kg.items()}
        res = analyze_channels(chunks, rate, kto, p, kg)
        ms: list[Measurement] = [
            Measurement("record length", record_s, "s", lo=p.min_record_s,
                        note=f"{sum(1 for n in self.chunk_names() if n in ctx.spans)} of "
                             f"{len(self.chunk_names())} chunks in {len(spans)} continuous stretch(es)"),
            Measurement("samples lost", lost / max(total, 1), "fraction", hi=p.max_lost_fraction),
        ]
        for r in res.values():
            ms += r.measurements(p)
        values = {
            "bias_instability_urad_per_s": {ch: r.bi.B if r.bi else None for ch, r in res.items()},
            "arw_urad_per_sqrt_s": {ch: r.arw.N if r.arw else None for ch, r in res.items()},
        }
        pickoff = {}
        for ch in GYRO_CHANNELS:
            v = np.concatenate(chunks[_pickoff(ch)])
            v = v[np.isfinite(v)] * 1e3 / kg[ch]
            pickoff[ch] = (float(v.mean()), float(v.std())) if len(v) else (math.nan, math.nan)
        md = _markdown(res, p, kto, kto_source, record_s, lost, total, pickoff,
                       any(src != "nominal" for _, src in got_kg.values()))
        figures = [
            Figure("allan", "Overlapping Allan deviation of the torquing rate -K_TO V_T per channel, with 68 % "
                   "confidence intervals (Greenhall EDF), the tau^-1/2 fit (ARW) and the bias-instability floor",
                   lambda path: plot_allan(path, res, p)),
            Figure("null", f"Torquing rate, {p.average_s:g}-s means, over the {_hours(record_s)} record (mean "
                   "removed): the null-stability wander", lambda path: plot_null(path, res, p)),
        ]
        return Analysis(values, ms, figures, md)


# ---------------------------------------------------------------------------- per channel
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

    def measurements(self, p: Params) -> list[Measurement]:
        ch = self.channel
        out = []
        if self.arw is not None:
            a = self.arw
            region = "a tau^-1/2 region" if a.white_region else "NOT a tau^-1/2 region: N is an upper bound"
            out.append(Measurement(f"ARW {ch}", a.N, "urad/sqrt(s)", lo=0.0, stderr=a.stderr,
                                   note=f"tau {a.tau_range_s[0]:g}..{a.tau_range_s[1]:g} s, free slope "
                                        f"{a.slope:+.2f} ({region}); loop white-rate level, not the gyro's alone"))
        else:
            out.append(Measurement(f"ARW {ch}", None, "urad/sqrt(s)", lo=0.0, note="; ".join(self.problems)))
        if self.bi is not None:
            b = self.bi
            floor = "floor reached" if b.floor_reached else "floor NOT reached (still falling): upper bound"
            out.append(Measurement(f"bias instability {ch}", b.B, "urad/s", lo=0.0, stderr=b.stderr,
                                   note=f"min sigma {b.sigma_min:.4g} urad/s at tau {b.tau_min_s:g} s / 0.664 "
                                        f"(tau >= {self.bi_min_tau_s:.3g} s); {floor}"))
        else:
            out.append(Measurement(f"bias instability {ch}", None, "urad/s", lo=0.0, note="; ".join(self.problems)))
        if self.loop is not None:
            lg = self.loop
            out.append(Measurement(f"caging loop gain G_p {ch}", lg.gain_per_s, "1/s",
                                   note=f"torquing rate per pickoff angle, "
                                        f"{lg.band_hz[0]:.3g}..{lg.band_hz[1]:.3g} Hz; "
                                        f"pickoff output {lg.pickoff_asd:.3g} urad/sqrt(Hz) there, through it: "
                                        f"N_loop {lg.white_rate:.3g} urad/sqrt(s)"))
        if self.null is not None:
            n = self.null
            out.append(Measurement(f"null stability {ch}, p-p of {n.avg_s:g}-s means over {_hours(n.record_s)}",
                                   n.peak_to_peak, "urad/s"))
            how = ("measured" if n.measured_over_span else
                   f"estimated: x {n.ratio:.3g} from the Allan deviation, extrapolated beyond tau "
                   f"{n.extrapolated_from_tau_s:g} s with slope {n.extrapolation_slope:+.2f}")
            out.append(Measurement(f"null stability {ch}, {_hours(n.span_s)} p-p", n.estimate, "urad/s", note=how))
        return out


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
                     p: Params, kg_mV_per_urad: dict[str, float] | None = None) -> dict[str, ChannelDrift]:
    """Per channel: rate r = -K_TO V (urad/s) split at gaps, its Allan deviation and read-offs.
    With the pickoff chunks and ``kg_mV_per_urad`` the loop gain is measured as well and the
    bias instability is read beyond ``p.bi_min_loop_tc`` loop time constants; without, beyond
    the ARW range."""
    out = {}
    band = (p.loop_band_lo_hz, p.loop_band_hi_frac * rate_hz)
    for ch in GYRO_CHANNELS:
        torq = chunks[_torq(ch)]
        segs = [s for c in torq for s in allan.split_finite(-kto[ch] * c)]
        if not segs:
            raise ProcedureError(f"channel {ch}: no gap-free data in the record")
        mean = float(np.average([s.mean() for s in segs], weights=[len(s) for s in segs]))
        res = allan.allan_deviation(segs, rate_hz)
        problems: list[str] = []
        loop = None
        if kg_mV_per_urad is not None and _pickoff(ch) in chunks:
            # the same gap-free stretches of both channels (a lost sample set is lost on all)
            both = [np.vstack([-kto[ch] * t, 1e3 * g / kg_mV_per_urad[ch]])
                    for t, g in zip(torq, chunks[_pickoff(ch)])]
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


# ---------------------------------------------------------------------------- report
def _markdown(res: dict[str, ChannelDrift], p: Params, kto: dict[str, float], kto_source: str, record_s: float,
              lost: int, total: int, pickoff: dict[str, tuple[float, float]], kg_measured: bool) -> str:
    nominal_note = ("" if "NOMINAL" not in kto_source else
                    "\n**K_TO: the rig's nominal data-sheet values were used** (no earth-rate result was given); "
                    "K_TO only scales the rates here, so every rate below scales with it.\n")
    lines = ["## Drift stability", "",
             f"Record: {_hours(record_s)} of the torquer outputs in Mode 3 at {p.rate_hz:g} Hz "
             f"({lost} of {total} samples lost); rate r = -K_TO V_T, K_TO from the {kto_source}: "
             + ", ".join(f"{c} {kto[c]:.4g}" for c in GYRO_CHANNELS) + " urad/s/V.", nominal_note,
             "| channel | ARW N (urad/sqrt s) | fit tau (s) | free slope | N_loop (urad/sqrt s) | "
             "bias instability B (urad/s) | read at tau >= (s) | tau at min (s) | floor | mean rate (urad/s) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for ch, r in res.items():
        a, b = r.arw, r.bi
        arw = (f"{a.N:.4g} ({a.lo:.3g}..{a.hi:.3g})", f"{a.tau_range_s[0]:g}..{a.tau_range_s[1]:g}",
               f"{a.slope:+.2f}" + ("" if a.white_region else " (not -1/2)")) if a else ("-", "-", "-")
        nloop = f"{r.loop.white_rate:.3g}" if r.loop else "-"
        bis = (f"{b.B:.4g} ({b.lo:.3g}..{b.hi:.3g})", f"{r.bi_min_tau_s:.3g}", f"{b.tau_min_s:g}",
               "reached" if b.floor_reached else "not reached: upper bound") if b else ("-", "-", "-", "-")
        lines.append(f"| {ch} | {' | '.join(arw)} | {nloop} | {' | '.join(bis)} | {r.mean_rate:+.4g} |")
    lines += ["", "Intervals are 68 % (one sigma) chi-square intervals from Greenhall's equivalent degrees of "
              "freedom. N is the value at tau = 1 s of the tau^-1/2 line through the stated range "
              "(IEEE 952 Annex C); B is the minimum Allan deviation at tau >= the \"read at\" column with "
              f"at least {p.min_edf:g} degrees of freedom for flicker noise, divided by 0.664; \"not reached\" means "
              "the minimum is at the longest such tau and significantly below the curve three octaves earlier, so "
              "B is an upper bound.", "",
              "**What the short-tau slope is.** The torquer output is the caging loop's output: above the "
              "loop's bandwidth its proportional path passes the pickoff noise (rate = proportional gain G_p x "
              "pickoff noise angle, a white rate), and below it the loop passes the platform's own motion "
              "about the input axis. So N here is the white-rate level of the caged channel, an upper bound "
              "on the gyro's angle random walk, not the gyro's alone. N_loop is that white rate as the "
              "record shows it: G_p (measured as the torquing rate per pickoff angle above the loop's "
              "bandwidth) times the pickoff's noise there, over sqrt(2). Where N is close to N_loop, the "
              "short-tau slope is the loop's, and the gyro's own N is not visible under it. ", "",
              f"**Where B is read.** The torquer follows the drift only below the loop's bandwidth, and a PI "
              f"loop's overshoot lifts the flicker's Allan deviation above its floor for several time "
              f"constants beyond it, so B is read at tau >= {p.bi_min_loop_tc:g} loop time constants 1/G_p "
              "(measured per channel); the loop's own contributions fall as 1/tau there.", "",
              f"## Null stability ({p.average_s:g}-s means; thesis Table 1 style, peak-to-peak)", "",
              f"| channel | p-p over the record (urad/s) | record | {_hours(p.null_span_s)} p-p (urad/s) | how |",
              "|---|---|---|---|---|"]
    for ch, r in res.items():
        n = r.null
        if n is None:
            lines.append(f"| {ch} | - | - | - | {'; '.join(r.problems)} |")
            continue
        how = ("measured" if n.measured_over_span else
               f"estimate: record p-p x {n.ratio:.3g}")
        lines.append(f"| {ch} | {n.peak_to_peak:.4g} | {_hours(n.record_s)} ({n.n_averages} means) | "
                     f"{n.estimate:.4g} | {how} |")
    if any(r.null and not r.null.measured_over_span for r in res.values()):
        lines += ["", f"The {_hours(p.null_span_s)} figure is an estimate: the record's peak-to-peak times the "
                  "ratio of the rms wander of the means expected over the longer span to that over the record. "
                  "The expected wander variance is half the sum of the Allan variances at the averaging time and "
                  "its octaves up to the span (a Haar decomposition); beyond the longest tau with enough degrees "
                  "of freedom the Allan deviation is continued with its last octave's slope clamped to 0..+1/2 "
                  "(flat: flicker floor; +1/2: rate random walk). A slow trend or temperature cycle the record "
                  "did not see is not in the estimate."]
    lines += ["", "## Pickoffs (the loops held them at null)", "",
              f"Pickoff scale K_g: {'stopwatch result' if kg_measured else 'nominal data-sheet values'}.", "",
              "| channel | mean (urad) | rms about mean (urad) |", "|---|---|---|"]
    lines += [f"| {ch} | {m:+.3g} | {s:.3g} |" for ch, (m, s) in pickoff.items()]
    probs = [f"- {ch}: {q}" for ch, r in res.items() for q in r.problems]
    if probs:
        lines += ["", "## Problems", "", *probs]
    return "\n".join(lines)


COLORS = {"X": "C0", "Y": "C1", "Z": "C2", "XRD": "C3"}


def plot_allan(path: Path, res: dict[str, ChannelDrift], p: Params) -> None:
    fig, axes = new_figure(figsize=(9.0, 6.0))
    ax = axes.flat[0]
    for ch, r in res.items():
        a = r.adev
        ok = np.isfinite(a.lo)
        c = COLORS.get(ch)
        ax.errorbar(a.tau_s[ok], a.dev[ok], yerr=[a.dev[ok] - a.lo[ok], a.hi[ok] - a.dev[ok]], fmt="o-", ms=3,
                    color=c, capsize=2, lw=1, label=ch)
        if r.arw is not None:
            t = np.array(r.arw.tau_range_s)
            ax.plot(t, r.arw.N / np.sqrt(t), "--", color=c, lw=2.5, alpha=0.6)
        if r.bi is not None:   # the floor over the taus it was read from, the minimum ringed
            ax.plot([r.bi_min_tau_s, r.bi.tau_max_s], [r.bi.sigma_min] * 2, ":", color=c, lw=1.5)
            ax.plot([r.bi.tau_min_s], [r.bi.sigma_min], "o", mfc="none", mec=c, ms=10)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("averaging time tau (s)")
    ax.set_ylabel("Allan deviation of -K_TO V_T (urad/s)")
    ax.set_title(f"Drift stability, Mode 3 (dashed: tau^-1/2 fit {p.arw_tau_lo_s:g}..{p.arw_tau_hi_s:g} s; "
                 "dotted: floor 0.664 B over the taus it is read from)", fontsize=10)
    ax.grid(True, which="major", alpha=0.5)
    ax.grid(True, which="minor", alpha=0.15)
    ax.legend()
    save_figure(fig, path)


def plot_null(path: Path, res: dict[str, ChannelDrift], p: Params) -> None:
    fig, axes = new_figure(figsize=(9.0, 5.0))
    ax = axes.flat[0]
    span = max((r.null.record_s for r in res.values() if r.null is not None), default=0.0)
    unit, unit_name = (3600.0, "h") if span >= 7200 else (60.0, "min")
    for ch, r in res.items():
        if r.null is None or len(r.null.means) == 0:
            continue
        m = r.null.means
        t = (np.arange(len(m)) + 0.5) * p.average_s / unit
        ax.plot(t, m - m.mean(), ".-", color=COLORS.get(ch), label=f"{ch}: p-p {r.null.peak_to_peak:.3g} urad/s")
    ax.set_xlabel(f"time in the record ({unit_name}; gaps and resumes closed up)")
    ax.set_ylabel(f"{p.average_s:g}-s mean rate - record mean (urad/s)")
    ax.grid(True, alpha=0.4)
    ax.legend(fontsize=8)
    save_figure(fig, path)


PROCEDURE = Drift
