"""The hysteresis analysis: Dahl's To and eta of a gimbal bearing, its loops and describing
function, from any "fbs-run" file of a torque-angle sweep (thesis Ch. V F, Figs. 50-57). A file
(and optionally the data sheet) in, ``HysteresisResult`` out; no rig. The procedure that records
the sweep is ``procedures.calibrations.hysteresis``; the plots and the Markdown are
``procedures.reports.hysteresis``; ``fbs analyze hysteresis FILE --axis X`` runs this alone.

``analyze_file`` reads only the file: the angle from the instrumentation channel, the bearing
torque from the power-amplifier input with the platform's inertial and viscous torques removed
(``dahl.bearing_torque``), the cycles of constant amplitude from the command channel; Dahl's To
and eta are fitted by integrating eq. 5.2 along the measured angle (``dahl.fit_dahl_path``). It
gives the loops (Figs. 51, 53, 54), the describing function (eq. 5.12, Fig. 57) and the
small-motion stiffness eta To^2. Every instrument constant comes from the rig's data sheet
(``RigCalibration``: the run's own ``/meta/calibration`` for a file); none is a constant here.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.stats

from daq.reader import LOST_SAMPLES_NOTE, RunFile, lost_samples
from daq.runfile import RunFileError
from drivers.calibration import AXES, AutocollimatorConstants, PlatformConstants, RigCalibration
from procedures.analysis import dahl
from procedures.analysis.intervals import Estimate, judged

log = logging.getLogger(__name__)

URAD = 1e-6
#: the axes with a primary (two-axis) autocollimator, hence an instrumentation channel (DESIGN.md section 5)
AC_AXES = ("X", "Y")
#: the reported figures (DESIGN.md section 7), each a plain number for the swept axis
FIGURES = ("To_Nm", "eta_per_Nm", "stiffness_Nm_per_rad")
#: the lag is measured at the command's lines above this many torque bandwidths (where the
#: platform is a rigid body to the drive) and below this fraction of the sample rate
LAG_MIN_FC, LAG_MAX_FS = 2.0, 0.45
#: the angle-path bandwidths whose fit leaves a residual rms within this fraction of the least
#: are taken as equally plausible; the estimates along them bound the path choice's error
#: (``dahl.PathScan.envelope``). The residual's minimum is shallow against a model error that
#: the cutoff trades off (the platform's jitter, the sensor's noise): over 60 random rigs the
#: estimates at the minimum missed the truth by up to 6 % (eta, Y) while 10 % more residual
#: reached it (``bench/hysteresis_coverage.py``, docs/procedures/hysteresis.md)
PATH_TOLERANCE = 0.10


@dataclass
class Loop:
    """One amplitude: its synchronously averaged cycle and first harmonics."""

    amplitude_urad: float              # of the angle's fundamental
    command_amplitude_V: float
    n_cycles: int
    t0_s: float
    t1_s: float
    theta_urad: np.ndarray = field(repr=False)     # averaged cycle, phase bins
    torque_Nm: np.ndarray = field(repr=False)      # measured, less the segment's offset
    model_Nm: np.ndarray = field(repr=False)       # Dahl along the measured angle, fitted parameters
    describing_Nm_per_rad: complex = 0j            # measured first-harmonic torque / angle
    model_describing_Nm_per_rad: complex = 0j      # eq. 5.12 at this amplitude, fitted parameters
    residual_rms_Nm: float = 0.0
    offset_Nm: float = 0.0


@dataclass
class HysteresisResult:
    file: str
    axis: str
    frequency_hz: float
    To_Nm: float
    eta_per_Nm: float
    stiffness_Nm_per_rad: float
    To_se_Nm: float
    eta_se_per_Nm: float
    stiffness_se_Nm_per_rad: float
    correlation: float
    torque_cutoff_hz: float
    path_cutoff_hz: float
    scan: dahl.PathScan
    loops: list[Loop]
    residual_rms_Nm: float
    relative_residual: float           # residual rms / largest loop's torque half-range
    calibration_source: str            # "file" | "given" | "defaults"
    rate_hz: float
    #: a stretch of the largest loop for the time-history plot (Fig. 50): t, angle, torque, model
    history: dict[str, np.ndarray] = field(repr=False, default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    #: the angle's lag behind the power-amplifier input that was taken out, its standard error,
    #: and where it came from: "measured" (``dahl.measure_lag``), "given", or "none" (unmeasured)
    angle_lag_s: float = 0.0
    angle_lag_se_s: float = math.nan
    lag_source: str = "none"
    lag: dahl.LagMeasurement | None = None
    #: the figures with their 95 % intervals (cluster-robust over cycles, the lag's error in)
    estimates: dict[str, Estimate] = field(default_factory=dict)
    dof: int = 0

    def values(self) -> dict[str, Any]:
        """The summary keys of DESIGN.md section 7, per axis as every procedure's figures
        (issue 37; the excitation's stiffness too): ``K`` {axis: value, None if unresolved},
        ``K_ci95`` {axis: [lo, hi]} and ``resolved`` {K: {axis: bool}}."""
        out: dict[str, Any] = {}
        resolved: dict[str, dict[str, bool]] = {}
        for key in FIGURES:
            e = self.estimates.get(key)
            value = getattr(self, key) if e is None else e.value if e.resolved else None
            out[key] = {self.axis: value}
            resolved[key] = {self.axis: value is not None and math.isfinite(value)}
        for key in FIGURES:
            e = self.estimates.get(key)
            out[f"{key}_ci95"] = {self.axis: [e.lo, e.hi] if e is not None else None}
        out["resolved"] = resolved
        out["angle_lag_ms"] = self.angle_lag_s * 1e3
        out["file"] = self.file
        return out

    def theta_o_bar(self, loop: Loop) -> float:
        """Normalized amplitude eta To theta_o (eq. 5.6b)."""
        return self.eta_per_Nm * self.To_Nm * loop.amplitude_urad * URAD


def calibration_from_meta(data: Any) -> RigCalibration | None:
    """The ``RigCalibration`` a run recorded in ``/meta/calibration`` (``dataclasses.asdict``
    of it); None if there is none. Unknown keys (a newer writer) are ignored."""
    if not isinstance(data, Mapping) or not data:
        return None
    names = {f.name for f in dataclasses.fields(RigCalibration)}
    kw = {k: v for k, v in data.items() if k in names}
    try:
        if "platform" in kw:
            kw["platform"] = {a: _make(PlatformConstants, v) for a, v in kw["platform"].items()}
        if "autocollimator" in kw:
            kw["autocollimator"] = {a: _make(AutocollimatorConstants, v) for a, v in kw["autocollimator"].items()}
        cal = RigCalibration(**kw)
    except (TypeError, AttributeError, ValueError) as exc:
        raise ValueError(f"/meta/calibration is not a rig calibration ({exc})") from None
    for where, group in (("platform", cal.platform), ("autocollimator", cal.autocollimator)):
        for axis, consts in group.items():
            for f in dataclasses.fields(consts):
                v = getattr(consts, f.name)
                ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                if not ok or v < 0 or (v == 0 and f.name != "damping_Nms"):
                    raise ValueError(f"/meta/calibration: {where}.{axis}.{f.name} = {v!r} must be a finite positive "
                                     "number")
    return cal


def _make(cls: type, value: Any) -> Any:
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in dict(value).items() if k in names})


#: beyond this a channel is no voltage a rig recorded (an ADC reads +-10 V; a writer's amplifier
#: stage might reach tens): the arithmetic of the analysis would overflow on it
MAX_PLAUSIBLE_V = 1e6


def analyze_file(path: str | Path, axis: str = "X", calibration: RigCalibration | None = None, *,
                 settle_cycles: int = 1, angle_lag_s: float | None = None, bins: int = 200) -> HysteresisResult:
    """Dahl's To and eta, the loops and the describing function from any "fbs-run" file with
    ``cmd_<a>``, ``ac_<a>_inst`` and ``pa_<a>`` channels recorded during a sinusoidal command
    at one frequency and a ladder of amplitudes (``settle_cycles`` at each new amplitude are
    left out). ``calibration`` defaults to the file's ``/meta/calibration``, else the data
    sheet's defaults (with a warning). The recorded angle is advanced by its lag behind the
    power-amplifier input (the instrumentation channel's filters, eq. 3.22, and the motor's
    La/Ra), measured on the record at the command's DAC lines (``dahl.measure_lag``); a number
    ``angle_lag_s`` overrides the measurement (for studies; its error is then taken as 0).
    Raises ValueError naming what is wrong."""
    path = Path(path)
    a = str(axis).upper()
    if a not in AXES:
        raise ValueError(f"unknown axis {axis!r} (the platform axes are {', '.join(AXES)})")
    if a not in AC_AXES:
        raise ValueError(f"axis {a} has no instrumentation autocollimator channel (ac_{a.lower()}_inst) to measure "
                         f"the angle with; the hysteresis analysis works on {' or '.join(AC_AXES)}")
    names = (f"cmd_{a.lower()}", f"ac_{a.lower()}_inst", f"pa_{a.lower()}")
    warnings: list[str] = []
    try:
        with RunFile(path) as rf:
            missing = [c for c in names if c not in rf.channels]
            if missing:
                raise ValueError(f"{path}: no channel(s) {', '.join(missing)} for axis {a} "
                                 f"(the file has {', '.join(rf.channels)})")
            fs = rf.rate_hz
            data = rf.read(list(names))
            meta = rf.meta
    except RunFileError as exc:
        raise ValueError(str(exc)) from None
    source = "given"
    if calibration is None:
        calibration = calibration_from_meta(meta.get("calibration"))
        source = "file"
        if calibration is None:
            calibration = RigCalibration()
            source = "defaults"
            msg = (f"{path.name} records no rig calibration (/meta/calibration): using the data sheet's "
                   f"default constants")
            log.warning(msg)
            warnings.append(msg)
    if a not in calibration.platform or a not in calibration.autocollimator:
        raise ValueError(f"axis {a!r}: the rig calibration has no platform and instrumentation-autocollimator "
                         f"constants for it (axes with both: "
                         f"{', '.join(sorted(set(calibration.platform) & set(calibration.autocollimator)))})")
    plat, ac = calibration.platform[a], calibration.autocollimator[a]
    for name, x in zip(names, data):
        peak = float(np.nanmax(np.abs(x))) if np.isfinite(x).any() else 0.0
        if peak > MAX_PLAUSIBLE_V or np.isinf(x).any():
            raise ValueError(f"{path}: {name} reaches {peak:.3g} V (or infinity): beyond the {MAX_PLAUSIBLE_V:g} V "
                             "of any recorded voltage; the file is damaged or not a rig's record")
    cmd, inst, pa = data
    if len(cmd) < 16:
        raise ValueError(f"{path}: {len(cmd)} samples are too few for an analysis")
    # lost samples of the command read as 0 here: where they break the sweep, the error says so
    cmd_lost = lost_samples(names[0], cmd, fs)
    lost_why = f"; {cmd_lost} ({LOST_SAMPLES_NOTE})" if cmd_lost else ""
    try:
        freq = dahl.command_frequency(np.nan_to_num(cmd), fs)
    except ValueError as exc:
        raise ValueError(f"{exc}{lost_why}") from None
    segments = dahl.find_segments(np.nan_to_num(cmd), fs, freq, settle_cycles=settle_cycles)
    if not segments:
        raise ValueError(f"{path}: {names[0]} has no run of at least {2 + settle_cycles} cycles at one amplitude "
                         f"(a sinusoid near {freq:.4g} Hz); too short, or not a hysteresis sweep{lost_why}")
    # the torque band: the fundamental and its harmonics well into the loops' corners
    fc = min(12.5 * freq, 0.2 * fs)
    finite = np.isfinite(data).all(axis=0)
    if not finite.all():
        # Lost samples (a dropped ADC frame): analysed around, never spliced over. The filters
        # run over the whole record, so the lost stretch is bridged by a straight line for them
        # alone, and every cycle within the filters' reach of it is left out (``_around_lost``).
        lost_where = "; ".join(t for t in (lost_samples(n, x, fs) for n, x in zip(names, data)) if t)
        margin = int(math.ceil(LOST_MARGIN_CORNER_PERIODS * fs / fc)) + LOST_MARGIN_SAMPLES
        segments, left_out = _around_lost(segments, np.flatnonzero(~finite), margin, fs / freq)
        if not segments:
            raise ValueError(f"{path}: {lost_where}; no run of at least 2 whole cycles at one amplitude is "
                             f"{margin} samples clear of them ({LOST_SAMPLES_NOTE})")
        good = np.flatnonzero(finite)
        data = np.array([np.interp(np.arange(data.shape[1]), good, x[good]) for x in data])
        cmd, inst, pa = data
        msg = (f"{lost_where}: analysed around ({', '.join(left_out)}; cycles within {margin} samples of a lost "
               f"one are left out)")
        log.warning(msg)
        warnings.append(msg)
    ac_scale = ac.inst_mV_per_urad * 1e-3 / URAD          # V per rad
    lag_meas: dahl.LagMeasurement | None = None
    if angle_lag_s is None:
        kt, dv, inertia = plat.torque_per_pa_V, plat.viscous_Nms, plat.inertia_kg_m2

        def rigid(w: np.ndarray) -> np.ndarray:
            # angle per volt of drive of the platform as a rigid body (eq. 3.23-3.27): the
            # bearing's small-motion stiffness is far below I w^2 at the lines used
            return kt / (-inertia * w * w + 1j * dv * w)

        try:
            lag_meas = dahl.measure_lag(cmd, inst / ac_scale, pa, fs, freq, segments, rigid,
                                        min_hz=LAG_MIN_FC * fc, max_hz=LAG_MAX_FS * fs)
            lag_s, lag_se, lag_source = lag_meas.lag_s, lag_meas.se_s, "measured"
        except ValueError as exc:
            msg = f"the angle's lag behind the power-amplifier input could not be measured ({exc}): none taken out"
            log.warning(msg)
            warnings.append(msg)
            lag_s, lag_se, lag_source = 0.0, math.nan, "none"
    else:
        lag_s, lag_se, lag_source = float(angle_lag_s), 0.0, "given"
    if not (math.isfinite(lag_s) and abs(lag_s) * fs < 20):
        raise ValueError(f"angle lag {lag_s * 1e3:g} ms must be finite and under 20 samples")
    theta = dahl.shift(inst / ac_scale, fs, lag_s)
    theta_f = dahl.lowpass(theta, fs, fc)
    torque = dahl.bearing_torque(dahl.lowpass(pa, fs, fc), theta_f, fs, torque_per_pa_Nm_per_V=plat.torque_per_pa_V,
                                 viscous_Nms=plat.viscous_Nms, inertia_kg_m2=plat.inertia_kg_m2)
    top = min(10.0 * fc, 0.35 * fs)
    cutoffs = [c for c in 1.25 * fc * 1.25 ** np.arange(20) if c <= top] or [fc]
    step = max(1, int(fs / (8.0 * fc)))
    fit, scan = dahl.fit_dahl_path(theta, torque, segments, fs, smooth_hz=fc, cutoffs_hz=cutoffs, step=step,
                                   independent_every=max(1, int(fs / (2.0 * fc))))
    path_cutoff_hz = fit.path_cutoff_hz
    assert path_cutoff_hz is not None  # fit_dahl_path sets it on the fit it returns
    if fit.path_cutoff_hz in (cutoffs[0], cutoffs[-1]) and len(cutoffs) > 1:
        msg = (f"the angle-path bandwidth that fits best, {fit.path_cutoff_hz:.3g} Hz, is at the end of the "
               f"range tried ({cutoffs[0]:.3g}..{cutoffs[-1]:.3g} Hz)")
        log.warning(msg)
        warnings.append(msg)
    model = np.full(len(theta), np.nan)
    model[fit.start:fit.stop] = fit.model_Nm
    chain = _Chain(inst / ac_scale, pa, cmd, fs, freq, fc, segments, plat, step, cutoffs,
                   rigid if lag_source == "measured" else None, lag_s,
                   lag_meas.frequencies_hz if lag_meas is not None else None)
    estimates, ses, dof = _jackknife(fit, chain, lag_source, scan.envelope(PATH_TOLERANCE))
    loops: list[Loop] = []
    k = fit.stiffness_Nm_per_rad
    for seg, off, rms in zip(segments, fit.offsets_Nm, fit.residual_rms_Nm):
        th_c = dahl.synchronous_average(theta_f, fs, freq, seg.start, seg.stop, bins)
        tq_c = dahl.synchronous_average(torque, fs, freq, seg.start, seg.stop, bins) - off
        md_c = dahl.synchronous_average(model, fs, freq, seg.start, seg.stop, bins) - off
        a1 = dahl.first_harmonic(th_c)
        n_meas = dahl.first_harmonic(tq_c) / a1
        amp = abs(a1)
        n_model = complex(dahl.describing_function(fit.eta_per_Nm * fit.To_Nm * amp)) * k
        loops.append(Loop(amp / URAD, seg.command_amplitude, seg.n_cycles, seg.start / fs, seg.stop / fs,
                          th_c / URAD, tq_c, md_c, n_meas, n_model, rms, off))
    big = max(range(len(loops)), key=lambda i: loops[i].amplitude_urad)
    half_range = 0.5 * float(np.ptp(loops[big].torque_Nm))
    relative = fit.residual_rms_total_Nm / half_range if half_range > 0 else math.inf
    s = segments[big]
    n_hist = min(s.stop - s.start, int(round(1.5 * fs / freq)))
    sl = slice(s.start, s.start + n_hist)
    history = {"t_s": np.arange(sl.start, sl.stop) / fs, "theta_urad": theta_f[sl] / URAD,
               "torque_Nm": torque[sl] - fit.offsets_Nm[big], "model_Nm": model[sl] - fit.offsets_Nm[big]}
    return HysteresisResult(str(path), a, freq, fit.To_Nm, fit.eta_per_Nm, k, ses[0] * fit.To_Nm,
                            ses[1] * fit.eta_per_Nm, ses[2] * k, fit.correlation, fc, float(path_cutoff_hz), scan,
                            loops, fit.residual_rms_total_Nm, relative, source, fs, history, warnings, lag_s, lag_se,
                            lag_source, lag_meas, estimates, dof)


def _half_width(parts: list[tuple[float, float]]) -> float:
    """95 % half-width of a sum of independent errors given as (standard uncertainty, degrees
    of freedom): t at the Welch-Satterthwaite degrees of freedom times the combined
    uncertainty (GUM G.4.1)."""
    u2 = sum(u * u for u, _ in parts)
    denom = sum(u ** 4 / dof for u, dof in parts if math.isfinite(dof) and dof > 0)
    nu = u2 * u2 / denom if denom > 0 else math.inf
    return float(scipy.stats.t.ppf(0.975, nu) if math.isfinite(nu) else scipy.stats.norm.ppf(0.975)) * math.sqrt(u2)


#: how far (in periods of the torque band's corner, plus samples for the lag and derivatives) a
#: lost sample reaches through the zero-phase filters: cycles nearer are left out
LOST_MARGIN_CORNER_PERIODS = 2.0
LOST_MARGIN_SAMPLES = 25


def _around_lost(segments: list[dahl.Segment], lost: np.ndarray, margin: int,
                 per: float) -> tuple[list[dahl.Segment], list[str]]:
    """Each segment cut to its longest run of whole cycles none of which is within ``margin``
    samples of a ``lost`` sample (at least 2 cycles, else the amplitude is left out); and what
    was left out, in words."""
    kept, said = [], []
    for seg in segments:
        per_seg = (seg.stop - seg.start) / seg.n_cycles
        clean = []
        for c in range(seg.n_cycles):
            a, b = seg.start + c * per_seg - margin, seg.start + (c + 1) * per_seg + margin
            clean.append(not np.any((lost >= a) & (lost < b)))
        if all(clean):
            kept.append(seg)
            continue
        best, run_start = (0, 0), None
        for c, ok in enumerate([*clean, False]):
            if ok and run_start is None:
                run_start = c
            elif not ok and run_start is not None:
                best = max(best, (c - run_start, -run_start))
                run_start = None
        n, first = best[0], -best[1]
        label = f"{seg.command_amplitude:.4g} V amplitude"
        if n >= 2:
            start = int(round(seg.start + first * per_seg))
            kept.append(dahl.Segment(start, int(round(seg.start + (first + n) * per_seg)), seg.lead_start, n,
                                     seg.command_amplitude))
            said.append(f"{seg.n_cycles - n} of {seg.n_cycles} cycles at the {label}")
        else:
            said.append(f"every cycle at the {label}")
    return kept, said


@dataclass
class _Chain:
    """The whole determination (lag, torque, path scan, fit) again, for a jackknife replicate."""

    angle_rad: np.ndarray
    pa: np.ndarray
    cmd: np.ndarray
    fs: float
    freq: float
    fc: float
    segments: list[dahl.Segment]
    plat: PlatformConstants
    step: int
    cutoffs: list[float]
    rigid: Callable[[np.ndarray], np.ndarray] | None     # None: the lag is not measured but held
    lag_s: float
    lines_hz: list[float] | None                         # the lines the full record's lag was measured at

    def __call__(self, drop: int, fit: dahl.DahlFit) -> tuple[float, float, float]:
        """(lag, ln To, ln eta) with the ``drop``-th kept cycle of every segment left out."""
        lag = self.lag_s
        if self.rigid is not None:
            lag = dahl.measure_lag(self.cmd, self.angle_rad, self.pa, self.fs, self.freq, self.segments, self.rigid,
                                   min_hz=LAG_MIN_FC * self.fc, max_hz=LAG_MAX_FS * self.fs, drop_cycle=drop,
                                   lines_hz=self.lines_hz).lag_s
        theta = dahl.shift(self.angle_rad, self.fs, lag)
        theta_f = dahl.lowpass(theta, self.fs, self.fc)
        torque = dahl.bearing_torque(dahl.lowpass(self.pa, self.fs, self.fc), theta_f, self.fs,
                                     torque_per_pa_Nm_per_V=self.plat.torque_per_pa_V,
                                     viscous_Nms=self.plat.viscous_Nms, inertia_kg_m2=self.plat.inertia_kg_m2)
        assert fit.path_cutoff_hz is not None
        # the path's bandwidth is chosen again, near the full record's choice
        near = sorted({*(c for c in self.cutoffs if fit.path_cutoff_hz / 1.6 <= c <= fit.path_cutoff_hz * 1.6),
                       fit.path_cutoff_hz})
        f, _ = dahl.fit_dahl_path(theta, torque, self.segments, self.fs, smooth_hz=self.fc, cutoffs_hz=near,
                                  step=self.step, drop_cycle=drop, start=(fit.To_Nm, fit.eta_per_Nm))
        return lag, math.log(f.To_Nm), math.log(f.eta_per_Nm)

    def without_amplitude(self, j: int, fit: dahl.DahlFit) -> tuple[float, float]:
        """(ln To, ln eta) fitted with the ``j``-th amplitude's cycles left out (the full
        record's lag and angle-path bandwidth; the model still runs along the whole path)."""
        theta = dahl.shift(self.angle_rad, self.fs, self.lag_s)
        torque = dahl.bearing_torque(dahl.lowpass(self.pa, self.fs, self.fc), dahl.lowpass(theta, self.fs, self.fc),
                                     self.fs, torque_per_pa_Nm_per_V=self.plat.torque_per_pa_V,
                                     viscous_Nms=self.plat.viscous_Nms, inertia_kg_m2=self.plat.inertia_kg_m2)
        assert fit.path_cutoff_hz is not None
        f = dahl.fit_dahl(dahl.lowpass(theta, self.fs, fit.path_cutoff_hz), torque,
                          [s for i, s in enumerate(self.segments) if i != j], self.fs, smooth_hz=self.fc,
                          step=self.step, start=(fit.To_Nm, fit.eta_per_Nm))
        return math.log(f.To_Nm), math.log(f.eta_per_Nm)


def _jackknife(fit: dahl.DahlFit, chain: _Chain, lag_source: str,
               path_choice: tuple[np.ndarray, np.ndarray]) -> tuple[dict[str, Estimate], list[float], int]:
    """To, eta and eta To^2 with 95 % intervals from three standard uncertainties (in ln):

    * within amplitudes: the whole chain (the lag measured, the torque formed, the path's
      bandwidth chosen, eq. 5.2 fitted) again with the j-th kept cycle of every segment left
      out, j = 0 .. G-1 (a delete-a-group jackknife over cycles: the errors of a cycle are
      correlated within it, hardly from one cycle to the next); G - 1 dof;
    * between amplitudes: the fit again with each amplitude's cycles left out, M - 1 dof.
      What is common to every cycle of an amplitude - where the model departs from the
      bearing in a way that depends on the amplitude (the platform's jitter the
      instrumentation channel cannot see, the stiff bearing's resonance in the angle path's
      band) - no resampling of cycles can see; it shows as the amplitudes disagreeing.
      Without it the intervals covered To 73 % and eta 58 % of the time over 60 rigs
      (``bench/hysteresis_coverage.py``). The amplitudes inform the figures unequally (the
      largest loops fix To): a plain delete-one jackknife then overstates the variance
      (Efron & Stein 1981), so each replicate is weighted by 1 - h_j, h_j the amplitude's
      leverage on that figure (``DahlFit.leverage``, its share of what the fit knows of it):
      Wu's weighted jackknife (Wu 1986, Ann. Statist. 14, eq. 2.4), sum_j (1 - h_j)
      (theta_(j) - theta)^2. With equal shares it is the plain jackknife's (M - 1) / M;
    * the angle path's bandwidth: ``path_choice`` (down, up) in ln, how far the estimates move
      over the bandwidths the residual cannot tell from the best (``PATH_TOLERANCE``): a bound,
      taken as a rectangular distribution, a / sqrt(3) (GUM 4.3.7), on each side.

    The spread between amplitudes holds the cycles' noise as well as the model's departure
    (each amplitude's cycles are noisy), so the two first terms are not added: the larger is
    taken (as a Birge-ratio or random-effects analysis does: a spread between groups no larger
    than within them reveals no error of the model). That one and the path's add in
    quadrature, and the half-width is Student's t at the Welch-Satterthwaite degrees of freedom
    (GUM G.4) times their sum. Over 180 rigs of ``bench/hysteresis_coverage.py`` this covered
    To 175 and eta 169 times (docs/procedures/hysteresis.md); three 95 % half-widths added in
    quadrature, with the plain jackknife, had covered To 100 of the first 100.
    Also returned: the relative standard errors (To, eta, stiffness; the cycles') and the
    cycles' degrees of freedom."""
    values = {"To_Nm": fit.To_Nm, "eta_per_Nm": fit.eta_per_Nm, "stiffness_Nm_per_rad": fit.stiffness_Nm_per_rad}
    G = min(s.n_cycles for s in chain.segments)
    if G < 2:
        return ({k: Estimate(v, math.nan, math.nan, False, f"{G} cycle per amplitude is too few for an interval")
                 for k, v in values.items()}, [math.nan] * 3, max(0, G - 1))

    def with_stiffness(ln: np.ndarray) -> np.ndarray:
        return np.column_stack([ln[:, 0], ln[:, 1], 2 * ln[:, 0] + ln[:, 1]])    # ln k = 2 ln To + ln eta

    reps = np.array([chain(j, fit) for j in range(G)])            # G x (lag, ln To, ln eta)
    lnc = with_stiffness(reps[:, 1:])
    se = np.sqrt((G - 1) / G * np.sum((lnc - lnc.mean(axis=0)) ** 2, axis=0))
    M = len(chain.segments)
    if M >= 3:
        ln_full = with_stiffness(np.log([[fit.To_Nm, fit.eta_per_Nm]]))[0]
        lna = with_stiffness(np.array([chain.without_amplitude(j, fit) for j in range(M)]))
        h = np.asarray(fit.leverage, dtype=float)
        w = 1.0 - h if h.shape == (M, 3) and np.all(np.isfinite(h)) else np.full((M, 3), (M - 1) / M)
        se_amp = np.sqrt(np.sum(w * (lna - ln_full) ** 2, axis=0))
    else:
        log.warning("%d amplitude(s): too few to judge the model by; the intervals hold the cycles' noise only", M)
        se_amp = np.zeros(3)
    down, up = path_choice
    out: dict[str, Estimate] = {}
    for i, (key, v) in enumerate(values.items()):
        # the amplitudes' spread holds their noise too: the larger of the two, not their sum
        noise = (float(se[i]), G - 1) if se[i] >= se_amp[i] else (float(se_amp[i]), M - 1)
        lo, hi = (v * math.exp(s * _half_width([noise, (a[i] / math.sqrt(3), math.inf)])) for s, a in ((-1, down), (1, up)))
        if lag_source == "none":
            out[key] = Estimate(v, lo, hi, False, "the angle's lag was not measured: the interval lacks its bias")
        else:
            # To and eta are told apart by the ladder reaching both regimes (the procedure's limits
            # on eta To theta_o), not by their correlation: each is judged by its own interval
            out[key] = judged(v, lo, hi)
    log.info("jackknife over %d cycle groups: lags %s ms", G, np.round(reps[:, 0] * 1e3, 3))
    return out, [float(x) for x in se], G - 1
