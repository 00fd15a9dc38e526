"""``survey``: the closed-loop spectral survey of Ch. V E (Figs. 42-49).

A Mode-3 record (autocollimator stabilization, gyros caged through their pickoffs) of the
primary autocollimator's control and instrumentation channels and the X-Y gyro's pickoffs.
From one Welch cross-spectral matrix of the record (``daq.filespectra.run_csd_matrix``)
the survey gives:

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
  docs/procedures/survey.md). ``Kg`` is the stopwatch procedure's measured value when its
  summary is given (``prior["stopwatch"]["K_g_mV_per_urad"]``), else the rig's nominal data
  sheet value, and the report says so.

* PSDs (urad^2/Hz) of the four autocollimator and two gyro channels, and the coherences
  autocollimator control - gyro per axis (Figs. 44/47), X - Y control channels (Fig. 48) and
  X - Y gyro (Fig. 49), as App. A.8 plots.

The measurement uses no thesis result. The thesis's numbers (1.6 / 3.6 urad, the 3.5 Hz
X dip) appear only in the report, as a reference column (``procedures.reports.thesis.SURVEY``, or whatever
the caller passes as ``reference``).

The record is taken in steps of ``piece_s`` so an aborted survey can be resumed: each step
returns the file and sample span it recorded; ``analyze`` merges adjacent spans of one file
and averages the Welch segments of all spans (a resumed piece lives in the earlier file).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import scipy.ndimage
import scipy.signal

from daq.filespectra import RunCsd, run_csd_matrix
from daq.plots import plot_coherence, plot_psd
from daq.reader import RunFile
from daq.spectra import band_rms, coherence
from procedures.params import prior_value
from procedures.reports import thesis
from procedures.reports.plotting import new_figure, save_figure
from procedures.rigsetup import bring_to_mode3
from procedures.runner import Analysis, Context, Figure, Measurement, Procedure, ProcedureError, Span, Step

AXES = ("X", "Y")



def ac_ctl(axis: str) -> str:
    return f"ac_{axis.lower()}_ctl"


def ac_inst(axis: str) -> str:
    return f"ac_{axis.lower()}_inst"


def gyro(axis: str) -> str:
    return f"gyro_{axis.lower()}"


@dataclass
class SurveyParams:
    duration_s: float = 300.0
    rate_hz: float = 1000.0
    #: record in steps of this length (the unit an aborted run can be resumed by)
    piece_s: float = 60.0
    #: wait after reaching mode 3 (a rig already caged in mode 3 waits at most 5 s)
    settle_s: float = 30.0
    #: Welch segment length (Hann, 50 % overlap): bin spacing 1/seg_s
    seg_s: float = 16.0
    #: band of the gyro-deduced platform rms (the thesis's method: 0.4-15 Hz)
    band_lo_hz: float = 0.4
    band_hi_hz: float = 15.0
    #: where to look for the control-channel dip, and the smoothing of the dB spectrum
    dip_lo_hz: float = 0.5
    dip_hi_hz: float = 30.0
    dip_smooth_hz: float = 0.5
    #: quality limits: the dip's prominence, the fraction of Welch segments usable (no lost samples)
    min_dip_depth_db: float = 6.0
    min_segments_used: float = 0.9

    def __post_init__(self) -> None:
        if not (self.duration_s > 0 and self.rate_hz > 0 and self.piece_s > 0 and self.seg_s > 0):
            raise ValueError("survey: duration_s, rate_hz, piece_s and seg_s must be > 0")
        if self.settle_s < 0:
            raise ValueError(f"survey: settle_s = {self.settle_s} must be >= 0")
        if self.seg_s > self.duration_s:
            raise ValueError(f"survey: a Welch segment of {self.seg_s} s is longer than the record "
                             f"({self.duration_s} s)")
        nyq = self.rate_hz / 2
        if not 0 < self.band_lo_hz < self.band_hi_hz <= nyq:
            raise ValueError(f"survey: band {self.band_lo_hz}..{self.band_hi_hz} Hz must lie in 0..{nyq:g} Hz")
        if not 0 < self.dip_lo_hz < self.dip_hi_hz <= nyq:
            raise ValueError(f"survey: dip search {self.dip_lo_hz}..{self.dip_hi_hz} Hz must lie in 0..{nyq:g} Hz")
        if self.dip_smooth_hz < 0:
            raise ValueError("survey: dip_smooth_hz must be >= 0")


# ---------------------------------------------------------------------------- analysis helpers
@dataclass(frozen=True)
class Dip:
    freq_hz: float
    depth_db: float          # prominence of the minimum in the smoothed dB spectrum
    bin_hz: float            # the smoothed spectrum's lowest bin (before the parabola)


def smoothed_db(f: np.ndarray, p: np.ndarray, smooth_hz: float) -> np.ndarray:
    """10 log10 of a PSD, averaged in dB over a running window of ``smooth_hz`` (ends held)."""
    df = float(f[1] - f[0])
    k = max(1, int(round(smooth_hz / df)))
    floor = np.finfo(float).tiny
    db = 10.0 * np.log10(np.maximum(np.asarray(p, float), floor))
    return scipy.ndimage.uniform_filter1d(db, k, mode="nearest") if k > 1 else db


def find_dip(f: np.ndarray, p: np.ndarray, lo_hz: float, hi_hz: float, smooth_hz: float) -> Dip | None:
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
    x = f[a:b + 1] - f[i]
    freq = float(f[i])
    if x.size >= 3:
        c2, c1, _ = np.polyfit(x, db[a:b + 1], 2)
        if c2 > 0:
            vertex = -c1 / (2 * c2)
            if abs(vertex) <= half * df:
                freq = float(f[i] + vertex)
    return Dip(freq, depth, float(f[i]))


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


def spans_csd(spans: Sequence[Span], channels: Sequence[str], seg_s: float) -> SpanCsd:
    """Welch cross-spectral matrix over the given file spans (segments never straddle two
    spans; a span shorter than a segment, or a file that is gone, is left out with a note)."""
    notes: list[str] = []
    parts: list[RunCsd] = []
    seconds = 0.0
    for span in spans:
        file, start, stop = span.file, span.start, span.stop
        try:
            with RunFile(file) as rf:
                nperseg = int(round(seg_s * rf.rate_hz))
                n = max(0, min(stop, rf.n_samples) - start)
                if n < nperseg:
                    notes.append(f"{Path(file).name} samples {start}..{stop}: shorter than one {seg_s:g} s segment, "
                                 f"left out")
                    continue
                parts.append(run_csd_matrix(rf, channels, nperseg=nperseg, start=start, stop=stop))
                seconds += n / rf.rate_hz
        except (OSError, ValueError) as exc:  # RunFileError is an OSError: a resumed piece's file may be gone
            notes.append(f"{Path(file).name} samples {start}..{stop}: not read ({exc})")
    if not parts:
        raise ProcedureError("survey: no recorded span could be analysed: " + "; ".join(notes or ["nothing recorded"]))
    fs = {p.fs for p in parts}
    if len(fs) != 1:
        raise ProcedureError(f"survey: the recorded spans have different sample rates {sorted(fs)} Hz")
    k = np.array([p.segments_used for p in parts], float)
    S = sum(p.S * kk for p, kk in zip(parts, k)) / k.sum()
    first = parts[0]
    return SpanCsd(first.f, S, tuple(channels), first.fs, first.nperseg, first.nfft, int(k.sum()),
                   sum(p.segments_total for p in parts), float(sum(p.dof for p in parts)), seconds, notes)


def pickoff_scales(prior: Mapping[str, Mapping[str, Any]], nominal: Mapping[str, float]
                   ) -> tuple[dict[str, float], dict[str, str]]:
    """Kg (mV/urad) per axis and where it came from: the stopwatch summary if given, else nominal."""
    got = {a: prior_value(prior, "stopwatch", "K_g_mV_per_urad", a, nominal[a]) for a in AXES}
    return {a: v for a, (v, _) in got.items()}, {a: src for a, (_, src) in got.items()}


# ---------------------------------------------------------------------------- the procedure
#: the name the module's functions and tests use
Params = SurveyParams


class Survey(Procedure[SurveyParams]):
    name = "survey"
    title = "Closed-loop spectral survey in Mode 3 (Ch. V E)"
    json_keys = ("platform_rms_urad", "dip_hz", "file")
    Params = SurveyParams
    mode = 3
    block_s = 1.0

    def __init__(self, params: SurveyParams | None = None, *, reference: Mapping[str, Any] | None = None, **kw) -> None:
        super().__init__(params, **kw)
        self.rate_hz = self.params.rate_hz
        #: the report's reference column (never used by the measurement)
        self.reference = dict(thesis.SURVEY if reference is None else reference)

    def channels(self) -> tuple[str, ...]:
        return tuple(ac_ctl(a) for a in AXES) + tuple(ac_inst(a) for a in AXES) + tuple(gyro(a) for a in AXES)

    def pieces(self) -> list[tuple[str, float]]:
        """(step name, seconds) of the record pieces."""
        p = self.params
        n = max(1, math.ceil(p.duration_s / p.piece_s - 1e-9))
        lengths = [p.piece_s] * (n - 1) + [p.duration_s - p.piece_s * (n - 1)]
        return [(f"record {i + 1}/{n}", seconds) for i, seconds in enumerate(lengths)]

    def plan(self) -> list[Step]:
        return [Step("mode 3", bring_to_mode3, expected_s=300.0, setup=True),
                Step("settle", self._settle, expected_s=self.params.settle_s, setup=True),
                *(Step(name, partial(self._record, seconds=seconds), expected_s=seconds)
                  for name, seconds in self.pieces())]

    def _settle(self, ctx: Context) -> dict:
        already = bool((ctx.results.get("mode 3") or {}).get("already"))
        seconds = min(5.0, self.params.settle_s) if already else self.params.settle_s
        ctx.acquire(seconds, keep=False)
        return {"settle_s": seconds}

    def _record(self, ctx: Context, seconds: float) -> dict:
        ctx.acquire(seconds, keep=False)   # where the samples are is the runner's record (ctx.spans)
        return {"seconds": seconds}

    # ------------------------------------------------------------------ analysis
    def analyze(self, ctx: Context) -> Analysis:
        p = self.params
        cal = ctx.rig.calibration
        csd = spans_csd(ctx.data_spans(name for name, _ in self.pieces()), self.channels(), p.seg_s)
        f = csd.f
        kac = {a: cal.autocollimator[a].control_mV_per_urad * 1e-3 for a in AXES}     # V/urad
        kai = {a: cal.autocollimator[a].inst_mV_per_urad * 1e-3 for a in AXES}
        kg_mv, kg_src = pickoff_scales(self.prior, cal.pickoff_scale_mV_per_urad)
        kg = {a: kg_mv[a] * 1e-3 for a in AXES}
        scale = {ac_ctl(a): kac[a] for a in AXES} | {ac_inst(a): kai[a] for a in AXES} | {gyro(a): kg[a] for a in AXES}
        psd_urad = {c: csd.psd(c) / scale[c] ** 2 for c in self.channels()}            # urad^2/Hz
        coh = coherence(csd.S)

        dips = {a: find_dip(f, psd_urad[ac_ctl(a)], p.dip_lo_hz, p.dip_hi_hz, p.dip_smooth_hz) for a in AXES}
        rms = {a: band_rms(f, psd_urad[gyro(a)], p.band_lo_hz, p.band_hi_hz) for a in AXES}
        ac_rms = {a: band_rms(f, psd_urad[ac_ctl(a)], p.band_lo_hz, p.band_hi_hz) for a in AXES}
        stiffness = {a: (cal.platform[a].inertia_kg_m2 * (2 * math.pi * d.freq_hz) ** 2
                         if (d := dips[a]) is not None else None) for a in AXES}
        used = csd.segments_used / max(1, csd.segments_total)

        values: dict[str, Any] = {
            "platform_rms_urad": {a: rms[a] for a in AXES},
            "dip_hz": {a: (d.freq_hz if (d := dips[a]) is not None else None) for a in AXES},
            "dip_depth_db": {a: (d.depth_db if (d := dips[a]) is not None else None) for a in AXES},
            "stiffness_from_dip_Nm_per_rad": stiffness,
            "ac_ctl_rms_urad": ac_rms,
            "pickoff_scale_mV_per_urad": kg_mv,
            "pickoff_scale_source": kg_src,
            "band_hz": [p.band_lo_hz, p.band_hi_hz],
            "record_s": csd.seconds,
        }
        ms: list[Measurement] = []
        for a in AXES:
            d = dips[a]
            ms.append(Measurement(f"dip {a} ({ac_ctl(a)})", d.freq_hz if d else None, "Hz",
                                  note=f"searched {p.dip_lo_hz:g}-{p.dip_hi_hz:g} Hz"))
            ms.append(Measurement(f"dip {a} depth (prominence)", d.depth_db if d else None, "dB",
                                  lo=p.min_dip_depth_db, note="no notch: the dip frequency is meaningless"
                                  if d is None or d.depth_db < p.min_dip_depth_db else ""))
            ms.append(Measurement(f"platform rms {a}, gyro-deduced {p.band_lo_hz:g}-{p.band_hi_hz:g} Hz", rms[a],
                                  "urad", note=f"Kg {kg_mv[a]:.4g} mV/urad ({kg_src[a]})"))
        ms.append(Measurement("Welch segments usable (no lost samples)", used, "", lo=p.min_segments_used,
                              note=f"{csd.segments_used} of {csd.segments_total}"))

        title = f"{Path(ctx.path).name}, Mode 3, {csd.seconds:.0f} s at {csd.fs:g} Hz, {csd.segments_used} segments"
        figures = [Figure("dip", "Autocollimator control-channel spectra (smoothed dB) over the dip search band, "
                          "with the dips found", lambda path: plot_dips(path, f, psd_urad, dips, p))]
        dof_bin = csd.dof
        for c in self.channels():
            figures.append(Figure(f"psd-{c}", f"PSD of {c} in urad²/Hz (App. A.8 display)",
                                  partial(plot_psd, f=f[1:-1], p=psd_urad[c][1:-1], channel=c, units="urad",
                                          dof=dof_bin, nperseg=csd.nperseg, nfft=csd.nfft, title=title)))
        idx = {c: i for i, c in enumerate(csd.channels)}
        pairs = [(ac_ctl("X"), gyro("X")), (ac_ctl("Y"), gyro("Y")), (ac_ctl("X"), ac_ctl("Y")), (gyro("X"), gyro("Y"))]
        for x, y in pairs:
            figures.append(Figure(f"coherence-{x}-{y}", f"Coherence {x} – {y}",
                                  partial(plot_coherence, f=f[1:-1], coh=coh[1:-1, idx[x], idx[y]], pair=(x, y),
                                          n_segments=csd.segments_used, title=title)))
        peak_coh = {}
        for x, y in pairs:
            band = (f >= 1.0) & (f <= 30.0)
            smooth = scipy.ndimage.uniform_filter1d(coh[band, idx[x], idx[y]], max(1, int(round(1.0 / (f[1] - f[0])))))
            k = int(np.argmax(smooth))
            peak_coh[(x, y)] = (float(f[band][k]), float(smooth[k]))
        md = self._markdown(values, dips, kg_src, csd, peak_coh)
        return Analysis(values, ms, figures, md)

    def _markdown(self, values: dict, dips: dict, kg_src: dict, csd: SpanCsd, peak_coh: dict) -> str:
        p = self.params
        ref = self.reference
        rref = ref.get("platform_rms_urad") or {}
        dref = ref.get("dip_hz") or {}

        def r(v, fmt=".3g"):
            return "-" if v is None else v if isinstance(v, str) else format(v, fmt)

        lines = ["## Survey", "",
                 f"Record: {csd.seconds:.0f} s at {csd.fs:g} Hz; Welch, Hann segments of {csd.nperseg / csd.fs:g} s "
                 f"(bin {csd.fs / csd.nfft:.4g} Hz), 50 % overlap, {csd.segments_used} of {csd.segments_total} "
                 f"segments used.", ""]
        src = ref.get("source", "reference")
        lines += [f"| quantity | X | Y | {src} X | {src} Y |", "|---|---|---|---|---|",
                  f"| dip of the control-channel spectrum (Hz) | {r(values['dip_hz']['X'], '.3f')} | "
                  f"{r(values['dip_hz']['Y'], '.3f')} | {r(dref.get('X'))} | {r(dref.get('Y'))} |",
                  f"| dip depth, prominence (dB) | {r(values['dip_depth_db']['X'], '.1f')} | "
                  f"{r(values['dip_depth_db']['Y'], '.1f')} | | |",
                  f"| bearing stiffness the dip implies, I (2 pi f)^2 (N m/rad) | "
                  f"{r(values['stiffness_from_dip_Nm_per_rad']['X'], '.4g')} | "
                  f"{r(values['stiffness_from_dip_Nm_per_rad']['Y'], '.4g')} | | |",
                  f"| platform rms, gyro-deduced, {p.band_lo_hz:g}-{p.band_hi_hz:g} Hz (urad) | "
                  f"{r(values['platform_rms_urad']['X'], '.3f')} | {r(values['platform_rms_urad']['Y'], '.3f')} | "
                  f"{r(rref.get('X'))} | {r(rref.get('Y'))} |",
                  f"| autocollimator control rms, {p.band_lo_hz:g}-{p.band_hi_hz:g} Hz (urad) | "
                  f"{r(values['ac_ctl_rms_urad']['X'], '.3f')} | {r(values['ac_ctl_rms_urad']['Y'], '.3f')} | | |",
                  f"| pickoff scale Kg used (mV/urad) | {values['pickoff_scale_mV_per_urad']['X']:.4g} "
                  f"({kg_src['X']}) | {values['pickoff_scale_mV_per_urad']['Y']:.4g} ({kg_src['Y']}) | | |", ""]
        lines += ["The gyro-deduced platform rms is the thesis's estimate (Ch. V E.2): the pickoff spectrum "
                  f"divided by Kg^2 and integrated over {p.band_lo_hz:g}-{p.band_hi_hz:g} Hz, taken as the platform "
                  "rms above 0.4 Hz because the platform does not respond above the loop bandwidth. It credits "
                  "all pickoff noise in the band to platform motion, so it over-states the true motion: it "
                  "measures sqrt(true^2 + pickoff noise^2) in the band (docs/procedures/survey.md).", ""]
        src_file = (self.prior.get("stopwatch") or {}).get("_from")
        if any(kg_src[a] == "stopwatch" for a in AXES):
            lines += [f"Kg from the stopwatch summary{f' `{src_file}`' if src_file else ''}.", ""]
        nominal = [a for a in AXES if kg_src[a] == "nominal"]
        if nominal:
            lines += [f"**Note:** no stopwatch result was given for {', '.join(nominal)}: the pickoff scale factor "
                      f"is the rig's nominal data-sheet value, so the platform rms scales with its error. Run "
                      f"`stopwatch` first (or pass its summary) for a measured Kg.", ""]
        lines += ["Coherence, largest 1-Hz average in 1-30 Hz:", ""]
        lines += [f"- {x} – {y}: {c:.2f} at {fk:.1f} Hz" for (x, y), (fk, c) in peak_coh.items()]
        lines.append("")
        for a in AXES:
            if dips[a] is None or dips[a].depth_db < p.min_dip_depth_db:
                lines += [f"**{a}: no clear dip** in {p.dip_lo_hz:g}-{p.dip_hi_hz:g} Hz (prominence "
                          f"{r(dips[a].depth_db if dips[a] else None, '.1f')} dB < {p.min_dip_depth_db:g} dB): "
                          f"the spectrum only slopes, as with viscous or no bearing restraint (Ch. V F).", ""]
        if csd.notes:
            lines += ["Spans left out: " + "; ".join(csd.notes), ""]
        return "\n".join(lines)


def plot_dips(path: Path, f: np.ndarray, psd_urad: dict, dips: dict, p: Params) -> None:
    fig, axes = new_figure(1, 1)
    ax = axes.flat[0]
    sel = (f >= p.dip_lo_hz) & (f <= p.dip_hi_hz)
    for k, a in enumerate(AXES):
        c = ac_ctl(a)
        ax.semilogx(f[sel], 10 * np.log10(np.maximum(psd_urad[c][sel], 1e-300)), color=f"C{k}", alpha=0.3,
                    linewidth=0.6)
        db = smoothed_db(f, psd_urad[c], p.dip_smooth_hz)
        ax.semilogx(f[sel], db[sel], color=f"C{k}", label=f"{c}, smoothed over {p.dip_smooth_hz:g} Hz")
        d = dips[a]
        if d is not None:
            ax.axvline(d.freq_hz, color=f"C{k}", linestyle="--",
                       label=f"dip {a}: {d.freq_hz:.3f} Hz, {d.depth_db:.1f} dB prominence")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("PSD (dB re 1 urad²/Hz)")
    ax.set_title("Mode 3: autocollimator control-channel spectra and their dips (Ch. V E.1)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    save_figure(fig, path)


PROCEDURE = Survey
