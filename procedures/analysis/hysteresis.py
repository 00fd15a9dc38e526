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
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.signal
import scipy.stats

from daq.reader import LOST_SAMPLES_NOTE, RunFile, lost_samples
from daq.runfile import RunFileError
from drivers.rig_datasheet import AXES, AutocollimatorConstants, PlatformConstants, RigCalibration
from procedures.analysis import dahl
from procedures.analysis.intervals import Estimate, judged
from procedures.analysis.threads import analysis_threads

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

    amplitude_urad: float  # of the angle's fundamental
    command_amplitude_V: float
    n_cycles: int
    t0_s: float
    t1_s: float
    theta_urad: np.ndarray = field(repr=False)  # averaged cycle, phase bins
    torque_Nm: np.ndarray = field(repr=False)  # measured, less the segment's offset
    model_Nm: np.ndarray = field(repr=False)  # Dahl along the measured angle, fitted parameters
    describing_Nm_per_rad: complex = 0j  # measured first-harmonic torque / angle
    model_describing_Nm_per_rad: complex = 0j  # eq. 5.12 at this amplitude, fitted parameters
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
    relative_residual: float  # residual rms / largest loop's torque half-range
    calibration_source: str  # "file" | "given" | "defaults"
    rate_hz: float
    #: a stretch of the largest loop for the time-history plot (Fig. 50): t, angle, torque, model
    history: dict[str, np.ndarray] = field(repr=False, default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    #: the angle's lag behind the power-amplifier input that was taken out, its standard error,
    #: and where it came from: "measured" at the command's lines (``dahl.measure_lag``),
    #: "fitted" with To and eta (a smooth command: ``dahl.fit_dahl``), or "given"
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
            kw["autocollimator"] = {
                a: _make(AutocollimatorConstants, v) for a, v in kw["autocollimator"].items()
            }
        cal = RigCalibration(**kw)
    except (TypeError, AttributeError, ValueError) as exc:
        raise ValueError(f"/meta/calibration is not a rig calibration ({exc})") from None
    for where, group in (("platform", cal.platform), ("autocollimator", cal.autocollimator)):
        for axis, consts in group.items():
            for f in dataclasses.fields(consts):
                v = getattr(consts, f.name)
                ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                if not ok or v < 0 or (v == 0 and f.name != "damping_Nms"):
                    raise ValueError(
                        f"/meta/calibration: {where}.{axis}.{f.name} = {v!r} must be a finite positive "
                        "number"
                    )
    return cal


def _make(cls: type, value: Any) -> Any:
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in dict(value).items() if k in names})


#: beyond this a channel is no voltage a rig recorded (an ADC reads +-10 V; a writer's amplifier
#: stage might reach tens): the arithmetic of the analysis would overflow on it
MAX_PLAUSIBLE_V = 1e6


def analyze_file(
    path: str | Path,
    axis: str = "X",
    calibration: RigCalibration | None = None,
    *,
    settle_cycles: int = 1,
    angle_lag_s: float | None = None,
    bins: int = 200,
) -> HysteresisResult:
    """Dahl's To and eta, the loops and the describing function from any "fbs-run" file with
    ``cmd_<a>``, ``ac_<a>_inst`` and ``pa_<a>`` channels recorded during a sinusoidal command
    at one frequency and a ladder of amplitudes (``settle_cycles`` at each new amplitude are
    left out). ``calibration`` defaults to the file's ``/meta/calibration``, else the data
    sheet's defaults (with a warning). The recorded angle is advanced by its lag behind the
    power-amplifier input (the instrumentation channel's filters, eq. 3.22, and the motor's
    La/Ra), measured on the record at the command's DAC lines (``dahl.measure_lag``), or, where
    the command carries none (a smooth sinusoid, as another lab's recorder drives it), fitted
    with To and eta along the whole record (``dahl.fit_dahl``); a number ``angle_lag_s``
    overrides both (for studies; its error is then taken as 0). A record sampled faster than
    the fit needs is decimated for it (``ANALYSIS_RATE_PER_FC``). Raises ValueError naming what
    is wrong."""
    path = Path(path)
    a = str(axis).upper()
    if a not in AXES:
        raise ValueError(f"unknown axis {axis!r} (the platform axes are {', '.join(AXES)})")
    if a not in AC_AXES:
        raise ValueError(
            f"axis {a} has no instrumentation autocollimator channel (ac_{a.lower()}_inst) to measure "
            f"the angle with; the hysteresis analysis works on {' or '.join(AC_AXES)}"
        )
    names = (f"cmd_{a.lower()}", f"ac_{a.lower()}_inst", f"pa_{a.lower()}")
    warnings: list[str] = []
    try:
        with RunFile(path) as rf:
            missing = [c for c in names if c not in rf.channels]
            if missing:
                raise ValueError(
                    f"{path}: no channel(s) {', '.join(missing)} for axis {a} "
                    f"(the file has {', '.join(rf.channels)})"
                )
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
            msg = (
                f"{path.name} records no rig calibration (/meta/calibration): using the data sheet's "
                f"default constants"
            )
            log.warning(msg)
            warnings.append(msg)
    if a not in calibration.platform or a not in calibration.autocollimator:
        raise ValueError(
            f"axis {a!r}: the rig calibration has no platform and instrumentation-autocollimator "
            f"constants for it (axes with both: "
            f"{', '.join(sorted(set(calibration.platform) & set(calibration.autocollimator)))})"
        )
    plat, ac = calibration.platform[a], calibration.autocollimator[a]
    for name, x in zip(names, data):
        peak = float(np.nanmax(np.abs(x))) if np.isfinite(x).any() else 0.0
        if peak > MAX_PLAUSIBLE_V or np.isinf(x).any():
            raise ValueError(
                f"{path}: {name} reaches {peak:.3g} V (or infinity): beyond the {MAX_PLAUSIBLE_V:g} V "
                "of any recorded voltage; the file is damaged or not a rig's record"
            )
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
        raise ValueError(
            f"{path}: {names[0]} has no run of at least {2 + settle_cycles} cycles at one amplitude "
            f"(a sinusoid near {freq:.4g} Hz); too short, or not a hysteresis sweep{lost_why}"
        )
    # the torque band: the fundamental and its harmonics well into the loops' corners
    fc = min(12.5 * freq, 0.2 * fs)
    finite = np.isfinite(data).all(axis=0)
    if not finite.all():
        # Lost samples (a dropped ADC frame): analysed around, never spliced over. The filters
        # run over the whole record, so the lost stretch is bridged by a straight line for them
        # alone, and every cycle within the filters' reach of it is left out (``_around_lost``).
        lost_where = "; ".join(
            t for t in (lost_samples(n, x, fs) for n, x in zip(names, data)) if t
        )
        margin = int(math.ceil(LOST_MARGIN_CORNER_PERIODS * fs / fc)) + LOST_MARGIN_SAMPLES
        segments, left_out = _around_lost(segments, np.flatnonzero(~finite), margin, fs / freq)
        if not segments:
            raise ValueError(
                f"{path}: {lost_where}; no run of at least 2 whole cycles at one amplitude is "
                f"{margin} samples clear of them ({LOST_SAMPLES_NOTE})"
            )
        good = np.flatnonzero(finite)
        data = np.array([np.interp(np.arange(data.shape[1]), good, x[good]) for x in data])
        cmd, inst, pa = data
        msg = (
            f"{lost_where}: analysed around ({', '.join(left_out)}; cycles within {margin} samples of a lost "
            f"one are left out)"
        )
        log.warning(msg)
        warnings.append(msg)
    ac_scale = ac.inst_mV_per_urad * 1e-3 / URAD  # V per rad
    lag_meas: dahl.LagMeasurement | None = None
    rigid = rigid_response(plat)
    if angle_lag_s is None:
        try:
            lag_meas = dahl.measure_lag(
                cmd,
                inst / ac_scale,
                pa,
                fs,
                freq,
                segments,
                rigid,
                min_hz=LAG_MIN_FC * fc,
                max_hz=LAG_MAX_FS * fs,
            )
            lag_s, lag_se, lag_source = lag_meas.lag_s, lag_meas.se_s, "measured"
        except ValueError as exc:
            # no line to measure it at (a smooth command): the lag is fitted with To and eta
            # (``dahl.fit_dahl``), from the data sheet's filters and La/Ra as a start only
            msg = (
                f"the angle's lag behind the power-amplifier input could not be measured at the command's lines "
                f"({exc}): it is fitted with To and eta"
            )
            log.info(msg)
            lag_s, lag_se, lag_source = datasheet_lag_s(plat, ac), math.nan, "fitted"
    else:
        lag_s, lag_se, lag_source = float(angle_lag_s), 0.0, "given"
    if not (math.isfinite(lag_s) and abs(lag_s) * fs < 20):
        raise ValueError(f"angle lag {lag_s * 1e3:g} ms must be finite and under 20 samples")
    # The fit needs the record up to the angle path's bandwidths (tens of Hz), not a fast
    # recorder's every sample: the channels are decimated alike (zero phase, so no lag between
    # them) to about ANALYSIS_RATE_PER_FC torque bandwidths, and the fit's cost no longer grows
    # with the sample rate (issue 38 item 7: 2.5 min on a fast record).
    q = max(1, int(fs // (ANALYSIS_RATE_PER_FC * fc)))
    fs_a = fs / q
    angle_rad, pa_a, cmd_a = (_decimate(x, q) for x in (inst / ac_scale, pa, cmd))
    seg_a = (
        [
            dahl.Segment(
                int(round(sg.start / q)),
                int(round(sg.stop / q)),
                int(round(sg.lead_start / q)),
                sg.n_cycles,
                sg.command_amplitude,
            )
            for sg in segments
        ]
        if q > 1
        else segments
    )
    fit_lag = lag_source == "fitted"
    max_fit_lag = min(FIT_LAG_RANGE_S, 15.0 / fs) if fit_lag else 0.0
    theta, theta_f, torque, lag_term = _torque(angle_rad, pa_a, fs_a, fc, plat, lag_s)
    top = min(10.0 * fc, 0.35 * fs_a)
    cutoffs = [c for c in 1.25 * fc * 1.25 ** np.arange(20) if c <= top] or [fc]
    step = max(1, int(fs_a / (8.0 * fc)))
    fit, scan = dahl.fit_dahl_path(
        theta,
        torque,
        seg_a,
        fs_a,
        smooth_hz=fc,
        cutoffs_hz=cutoffs,
        step=step,
        independent_every=max(1, int(fs_a / (2.0 * fc))),
        lag_term_Nm=lag_term if fit_lag else None,
        max_lag_s=max_fit_lag,
    )
    path_cutoff_hz = fit.path_cutoff_hz
    assert path_cutoff_hz is not None  # fit_dahl_path sets it on the fit it returns
    if fit.path_cutoff_hz in (cutoffs[0], cutoffs[-1]) and len(cutoffs) > 1:
        msg = (
            f"the angle-path bandwidth that fits best, {fit.path_cutoff_hz:.3g} Hz, is at the end of the "
            f"range tried ({cutoffs[0]:.3g}..{cutoffs[-1]:.3g} Hz)"
        )
        log.warning(msg)
        warnings.append(msg)
    base_lag = lag_s
    if fit_lag:
        # the fitted lag taken out: the angle, its low-passed copy and the torque formed again
        lag_s = base_lag + fit.lag_s
        theta, theta_f, torque, _ = _torque(angle_rad, pa_a, fs_a, fc, plat, lag_s)
    chain = _Chain(
        inst / ac_scale,
        pa,
        cmd,
        fs,
        freq,
        fc,
        segments,
        plat,
        step,
        cutoffs,
        rigid if lag_source == "measured" else None,
        lag_s,
        lag_meas.frequencies_hz if lag_meas is not None else None,
        angle_rad,
        pa_a,
        fs_a,
        seg_a,
        base_lag,
        max_fit_lag,
    )
    lag_choice = (np.zeros(3), np.zeros(3))
    if fit_lag:
        # The fitted lag takes up whatever of the model's error looks like a lag (the platform's
        # jitter the path lacks, a simulator's held friction torque): over the rigs of
        # tests/procedures/test_hysteresis.py it lay 0.4-0.8 ms beyond the instruments' own lag.
        # The data sheet's lag (its filters and La/Ra) is the other plausible choice: the
        # figures at it bound the lag's error (a rectangular bound, as the path's bandwidth)
        theta0, _, torque0, _ = _torque(angle_rad, pa_a, fs_a, fc, plat, base_lag)
        at_sheet = dahl.fit_dahl(
            dahl.lowpass(theta0, fs_a, path_cutoff_hz),
            torque0,
            seg_a,
            fs_a,
            smooth_hz=fc,
            step=step,
            start=(fit.To_Nm, fit.eta_per_Nm),
        )
        lag_choice = _choice(fit, at_sheet)
    drive_choice = _drive_choice(theta, torque, pa_a, fs_a, fc, plat, seg_a, step, cutoffs, fit)
    estimates, ses, dof, lags = _jackknife(
        fit, chain, lag_source, [scan.envelope(PATH_TOLERANCE), lag_choice, drive_choice]
    )
    if fit_lag:
        G = len(lags)
        lag_se = (
            float(np.sqrt((G - 1) / G * np.sum((lags - lags.mean()) ** 2))) if G >= 2 else math.nan
        )
    model = np.full(len(theta), np.nan)
    model[fit.start : fit.stop] = fit.model_Nm
    loops: list[Loop] = []
    k = fit.stiffness_Nm_per_rad
    for seg, off, rms in zip(seg_a, fit.offsets_Nm, fit.residual_rms_Nm):
        th_c = dahl.synchronous_average(theta_f, fs_a, freq, seg.start, seg.stop, bins)
        tq_c = dahl.synchronous_average(torque, fs_a, freq, seg.start, seg.stop, bins) - off
        md_c = dahl.synchronous_average(model, fs_a, freq, seg.start, seg.stop, bins) - off
        a1 = dahl.first_harmonic(th_c)
        n_meas = dahl.first_harmonic(tq_c) / a1
        amp = abs(a1)
        n_model = complex(dahl.describing_function(fit.eta_per_Nm * fit.To_Nm * amp)) * k
        loops.append(
            Loop(
                amp / URAD,
                seg.command_amplitude,
                seg.n_cycles,
                seg.start / fs_a,
                seg.stop / fs_a,
                th_c / URAD,
                tq_c,
                md_c,
                n_meas,
                n_model,
                rms,
                off,
            )
        )
    big = max(range(len(loops)), key=lambda i: loops[i].amplitude_urad)
    half_range = 0.5 * float(np.ptp(loops[big].torque_Nm))
    relative = fit.residual_rms_total_Nm / half_range if half_range > 0 else math.inf
    linear = linear_bearing_fit(
        dahl.lowpass(theta, fs_a, path_cutoff_hz), torque, seg_a, fs_a, fc, step
    )
    estimates = _applicable(estimates, fit, loops, linear)
    s = seg_a[big]
    n_hist = min(s.stop - s.start, int(round(1.5 * fs_a / freq)))
    sl = slice(s.start, s.start + n_hist)
    history = {
        "t_s": np.arange(sl.start, sl.stop) / fs_a,
        "theta_urad": theta_f[sl] / URAD,
        "torque_Nm": torque[sl] - fit.offsets_Nm[big],
        "model_Nm": model[sl] - fit.offsets_Nm[big],
    }
    return HysteresisResult(
        str(path),
        a,
        freq,
        fit.To_Nm,
        fit.eta_per_Nm,
        k,
        ses[0] * fit.To_Nm,
        ses[1] * fit.eta_per_Nm,
        ses[2] * k,
        fit.correlation,
        fc,
        float(path_cutoff_hz),
        scan,
        loops,
        fit.residual_rms_total_Nm,
        relative,
        source,
        fs,
        history,
        warnings,
        lag_s,
        lag_se,
        lag_source,
        lag_meas,
        estimates,
        dof,
    )


#: the fit runs at about this many torque bandwidths' worth of sample rate (400 Hz for a 0.4 Hz
#: drive, whose torque band is 5 Hz and whose angle paths reach 50 Hz); a faster record is
#: decimated to it
ANALYSIS_RATE_PER_FC = 80.0
#: a fitted lag is sought within this of the data sheet's (and within 15 samples)
FIT_LAG_RANGE_S = 0.01


def rigid_response(plat: PlatformConstants) -> Callable[[np.ndarray], np.ndarray]:
    """The platform's angle per volt of drive at angular frequencies w (rad/s) as a rigid body
    (eq. 3.23-3.27): the bearing's small-motion stiffness is far below I w^2 at the command
    lines the lag is measured at (``dahl.measure_lag``)."""
    kt, dv, inertia = plat.torque_per_pa_V, plat.viscous_Nms, plat.inertia_kg_m2

    def rigid(w: np.ndarray) -> np.ndarray:
        return kt / (-inertia * w * w + 1j * dv * w)

    return rigid


def datasheet_lag_s(plat: PlatformConstants, ac: AutocollimatorConstants) -> float:
    """The angle's lag behind the power-amplifier input by the data sheet, at low frequency:
    the group delays of the instrumentation channel's filters (eq. 3.22: 1/w1 for the first
    order, 2 zeta/w2 for the second) and of the motor's armature, La/Ra (eq. 3.25). Only the
    fitted lag's starting point: the record decides."""
    return (
        1.0 / ac.inst_filter1_rad_per_s
        + 2.0 * ac.inst_filter2_zeta / ac.inst_filter2_rad_per_s
        + plat.armature_H / plat.armature_ohm
    )


def _decimate(x: np.ndarray, q: int) -> np.ndarray:
    """Every ``q``-th sample of ``x`` after a zero-phase anti-alias low-pass (the same for every
    channel, so none lags another)."""
    if q <= 1:
        return np.asarray(x, dtype=float)
    return np.asarray(
        scipy.signal.decimate(np.asarray(x, dtype=float), q, ftype="fir", zero_phase=True)
    )


def _torque(
    angle_rad: np.ndarray,
    pa: np.ndarray,
    fs: float,
    fc: float,
    plat: PlatformConstants,
    lag_s: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The angle advanced by ``lag_s``, its copy low-passed at ``fc``, the bearing torque
    (``dahl.bearing_torque``, eq. 3.23-3.27) and that torque's part formed from the angle
    (-D thetadot - I thetaddot, which a further lag would move)."""
    theta = dahl.shift(angle_rad, fs, lag_s)
    theta_f = dahl.lowpass(theta, fs, fc)
    drive = plat.torque_per_pa_V * dahl.lowpass(pa, fs, fc)
    torque = dahl.bearing_torque(
        dahl.lowpass(pa, fs, fc),
        theta_f,
        fs,
        torque_per_pa_Nm_per_V=plat.torque_per_pa_V,
        viscous_Nms=plat.viscous_Nms,
        inertia_kg_m2=plat.inertia_kg_m2,
    )
    return theta, theta_f, torque, torque - drive


#: Dahl's To shows in the loops only where the bearing slips: the largest loop must reach this
#: normalized amplitude eta To theta_o (eq. 5.6b; its peak torque is then 0.62 To, eq. 5.9),
#: else To and eta are not determined apart (only the stiffness eta To^2 is)
MIN_COULOMB_X = 1.0
#: Dahl's friction must explain the torque better than a linear bearing (a spring and a damper,
#: T = k theta + c thetadot) does: its residual rms at most this fraction of the linear one's.
#: A Dahl bearing's loops leave a linear fit 10-40 times the residual; no friction, a viscous
#: bearing or a spring leave both alike (issue 38 item 1)
MAX_RESIDUAL_VS_LINEAR = 0.5


def linear_bearing_fit(
    path_rad: np.ndarray,
    torque_Nm: np.ndarray,
    segments: list[dahl.Segment],
    fs: float,
    smooth_hz: float,
    step: int,
) -> tuple[float, float, float]:
    """(k, c, residual rms) of the linear bearing T = k theta + c thetadot (a spring and a
    damper, Ch. III G) fitted like ``dahl.fit_dahl`` (the same samples, one offset per
    segment, the model low-passed alike): the alternative Dahl's model must beat."""
    cols = [
        dahl.lowpass(path_rad, fs, smooth_hz),
        dahl.lowpass(np.gradient(path_rad) * fs, fs, smooth_hz),
    ]
    rows, ys = [], []
    for sg in segments:
        i = np.arange(sg.start, sg.stop, max(1, step))
        X = np.column_stack([c[i] for c in cols])
        rows.append(X - X.mean(axis=0))
        ys.append(torque_Nm[i] - torque_Nm[i].mean())
    X, y = np.concatenate(rows), np.concatenate(ys)
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    return float(coef[0]), float(coef[1]), float(np.sqrt(np.mean((y - X @ coef) ** 2)))


def _applicable(
    estimates: dict[str, Estimate],
    fit: dahl.DahlFit,
    loops: list[Loop],
    linear: tuple[float, float, float],
) -> dict[str, Estimate]:
    """The estimates, with those whose model does not apply to the record unresolved and the
    reason stated (issue 38 item 1). Dahl's figures mean something only where the torque
    follows eq. 5.2: where the fit ends on the edge of its search, or explains the torque no
    better than a linear spring and damper (``linear``: k, c and its residual rms;
    ``MAX_RESIDUAL_VS_LINEAR``) - no friction, a viscous bearing, a spring - none of To, eta
    and eta To^2 is resolved; where the largest loop stays below ``MIN_COULOMB_X`` (the
    bearing never slips) To and eta are not determined apart. Their intervals are then
    [0, inf]: the data bound nothing the model can name."""
    k_lin, c_lin, r_lin = linear
    why_all = ""
    if fit.at_edge:
        why_all = (
            f"the fit ran to the edge of its search ({', '.join(fit.at_edge)}): the torque does not follow "
            f"Dahl's model (eq. 5.2), no bearing friction it describes"
        )
    elif not fit.residual_rms_total_Nm <= MAX_RESIDUAL_VS_LINEAR * r_lin:
        why_all = (
            f"Dahl's model (eq. 5.2) explains the torque no better than a linear bearing (spring {k_lin:.3g} "
            f"N m/rad, damper {c_lin:.3g} N m s: residual {r_lin * 1e3:.3g} mN m against Dahl's "
            f"{fit.residual_rms_total_Nm * 1e3:.3g}): no friction of eq. 5.2 in the record (none, viscous, "
            f"or a spring)"
        )
    x_max = max(
        (fit.eta_per_Nm * fit.To_Nm * lp.amplitude_urad * URAD for lp in loops), default=0.0
    )
    out: dict[str, Estimate] = {}
    for key, e in estimates.items():
        why = why_all
        if not why and key != "stiffness_Nm_per_rad" and not x_max >= MIN_COULOMB_X:
            why = (
                f"the largest loop reaches eta To theta_o = {x_max:.3g}, under {MIN_COULOMB_X:g}: the bearing never "
                f"slips (friction beyond the torques applied), so To and eta are not determined apart (eq. 5.9), "
                f"only eta To^2"
            )
        out[key] = Estimate(e.value, 0.0, math.inf, False, why) if why else e
    return out


def _half_width(parts: list[tuple[float, float]]) -> float:
    """95 % half-width of a sum of independent errors given as (standard uncertainty, degrees
    of freedom): t at the Welch-Satterthwaite degrees of freedom times the combined
    uncertainty (GUM G.4.1)."""
    u2 = sum(u * u for u, _ in parts)
    denom = sum(u**4 / dof for u, dof in parts if math.isfinite(dof) and dof > 0)
    nu = u2 * u2 / denom if denom > 0 else math.inf
    return float(
        scipy.stats.t.ppf(0.975, nu) if math.isfinite(nu) else scipy.stats.norm.ppf(0.975)
    ) * math.sqrt(u2)


#: how far (in periods of the torque band's corner, plus samples for the lag and derivatives) a
#: lost sample reaches through the zero-phase filters: cycles nearer are left out
LOST_MARGIN_CORNER_PERIODS = 2.0
LOST_MARGIN_SAMPLES = 25


def _around_lost(
    segments: list[dahl.Segment], lost: np.ndarray, margin: int, per: float
) -> tuple[list[dahl.Segment], list[str]]:
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
            kept.append(
                dahl.Segment(
                    start,
                    int(round(seg.start + (first + n) * per_seg)),
                    seg.lead_start,
                    n,
                    seg.command_amplitude,
                )
            )
            said.append(f"{seg.n_cycles - n} of {seg.n_cycles} cycles at the {label}")
        else:
            said.append(f"every cycle at the {label}")
    return kept, said


@dataclass
class _Chain:
    """The whole determination (lag, torque, path scan, fit) again, for a jackknife replicate."""

    angle_rad: np.ndarray  # the record at its own rate: the lag's lines are measured on it
    pa: np.ndarray
    cmd: np.ndarray
    fs: float
    freq: float
    fc: float
    segments: list[dahl.Segment]
    plat: PlatformConstants
    step: int
    cutoffs: list[float]
    rigid: Callable[[np.ndarray], np.ndarray] | None  # None: the lag is not measured at lines
    lag_s: float
    lines_hz: list[float] | None  # the lines the full record's lag was measured at
    angle_a: np.ndarray  # the record at the analysis rate (``ANALYSIS_RATE_PER_FC``): the fit's
    pa_a: np.ndarray
    fs_a: float
    seg_a: list[dahl.Segment]
    base_lag_s: float  # a fitted lag: where its search starts (the data sheet's)
    max_fit_lag_s: float  # > 0: the lag is fitted with To and eta

    def __call__(self, drop: int, fit: dahl.DahlFit) -> tuple[float, float, float]:
        """(lag, ln To, ln eta) with the ``drop``-th kept cycle of every segment left out."""
        lag = self.lag_s
        if self.rigid is not None:
            lag = dahl.measure_lag(
                self.cmd,
                self.angle_rad,
                self.pa,
                self.fs,
                self.freq,
                self.segments,
                self.rigid,
                min_hz=LAG_MIN_FC * self.fc,
                max_hz=LAG_MAX_FS * self.fs,
                drop_cycle=drop,
                lines_hz=self.lines_hz,
            ).lag_s
        fitted = self.max_fit_lag_s > 0
        theta, _, torque, term = _torque(
            self.angle_a,
            self.pa_a,
            self.fs_a,
            self.fc,
            self.plat,
            self.base_lag_s if fitted else lag,
        )
        assert fit.path_cutoff_hz is not None
        # the path's bandwidth is chosen again, near the full record's choice
        near = sorted(
            {
                *(
                    c
                    for c in self.cutoffs
                    if fit.path_cutoff_hz / 1.6 <= c <= fit.path_cutoff_hz * 1.6
                ),
                fit.path_cutoff_hz,
            }
        )
        f, _ = dahl.fit_dahl_path(
            theta,
            torque,
            self.seg_a,
            self.fs_a,
            smooth_hz=self.fc,
            cutoffs_hz=near,
            step=self.step,
            drop_cycle=drop,
            start=(fit.To_Nm, fit.eta_per_Nm, fit.lag_s),
            lag_term_Nm=term if fitted else None,
            max_lag_s=self.max_fit_lag_s,
        )
        if fitted:
            lag = self.base_lag_s + f.lag_s
        return lag, math.log(f.To_Nm), math.log(f.eta_per_Nm)

    def without_amplitude(self, j: int, fit: dahl.DahlFit) -> tuple[float, float]:
        """(ln To, ln eta) fitted with the ``j``-th amplitude's cycles left out (the full
        record's angle-path bandwidth, and its lag unless the lag is fitted; the model still
        runs along the whole path)."""
        fitted = self.max_fit_lag_s > 0
        theta, _, torque, term = _torque(
            self.angle_a,
            self.pa_a,
            self.fs_a,
            self.fc,
            self.plat,
            self.base_lag_s if fitted else self.lag_s,
        )
        assert fit.path_cutoff_hz is not None
        f = dahl.fit_dahl(
            dahl.lowpass(theta, self.fs_a, fit.path_cutoff_hz),
            torque,
            [s for i, s in enumerate(self.seg_a) if i != j],
            self.fs_a,
            smooth_hz=self.fc,
            step=self.step,
            start=(fit.To_Nm, fit.eta_per_Nm, fit.lag_s),
            lag_term_Nm=term if fitted else None,
            max_lag_s=self.max_fit_lag_s,
        )
        return math.log(f.To_Nm), math.log(f.eta_per_Nm)


def _drive_choice(
    theta: np.ndarray,
    torque: np.ndarray,
    pa: np.ndarray,
    fs: float,
    fc: float,
    plat: PlatformConstants,
    segments: list[dahl.Segment],
    step: int,
    cutoffs: list[float],
    fit: dahl.DahlFit,
) -> tuple[np.ndarray, np.ndarray]:
    """How far (ln To, ln eta, ln eta To^2) move when the angle path's content above its
    bandwidth is the drive's (``dahl.driven_angle``, the bearing a spring of the fitted
    stiffness) instead of nothing: (down, up), each >= 0.

    Why: the path is the instrumentation angle low-passed where the fit explains the torque
    best, and that choice is a compromise the residual cannot see through. Above it the
    platform really moves (the DAC's steps, its jitter), and the bearing ratchets on those
    reversals; the low-pass drops them, which reads eta high. Higher up, the angle shows the
    sensor's noise, reversals that are no motion at all, which reads eta low. On 16 offline
    sim rigs with the true angle recorded (``bench/hysteresis_paths.py``) the path of least
    residual read the stiffness +0.2 to +4.5 % high (median +0.8 %) where the true angle
    read -0.0 to +2.3 % (+0.15 %); with the angle above the bandwidth taken from the drive
    it read -7.5 to +0.1 % (-1.1 %), and the truth lay between the two 14 times (eta 12; To
    once, both reading it a little high). The drive's view is noise-free but approximate (the
    spring stands for a stiffness that runs 0 .. 4 eta To^2 along a loop), so neither path is
    the bearing's: how far the figures move from one to the other is taken as a rectangular
    bound, as the lag's and the bandwidth's are."""
    cut = fit.path_cutoff_hz
    if cut is None or not (fit.stiffness_Nm_per_rad > 0):
        return np.zeros(3), np.zeros(3)
    drive = dahl.driven_angle(
        pa,
        fs,
        torque_per_pa_Nm_per_V=plat.torque_per_pa_V,
        viscous_Nms=plat.viscous_Nms,
        inertia_kg_m2=plat.inertia_kg_m2,
        stiffness_Nm_per_rad=fit.stiffness_Nm_per_rad,
    )
    path = dahl.lowpass(theta, fs, cut) + drive - dahl.lowpass(drive, fs, cut)
    try:
        alt = dahl.fit_dahl(
            dahl.lowpass(path, fs, max(cutoffs)),
            torque,
            segments,
            fs,
            smooth_hz=fc,
            step=step,
            start=(fit.To_Nm, fit.eta_per_Nm),
        )
    except ValueError as exc:
        log.info("the drive's view of the angle gave no fit (%s): no bound from it", exc)
        return np.zeros(3), np.zeros(3)
    if alt.at_edge:
        return np.zeros(3), np.zeros(3)
    return _choice(fit, alt)


def _choice(fit: dahl.DahlFit, alt: dahl.DahlFit) -> tuple[np.ndarray, np.ndarray]:
    """How far (ln To, ln eta, ln eta To^2) move from ``fit`` to ``alt``: (down, up), each >= 0."""
    d = np.log(
        [
            alt.To_Nm / fit.To_Nm,
            alt.eta_per_Nm / fit.eta_per_Nm,
            alt.stiffness_Nm_per_rad / fit.stiffness_Nm_per_rad,
        ]
    )
    return np.maximum(-d, 0.0), np.maximum(d, 0.0)


def _jackknife(
    fit: dahl.DahlFit,
    chain: _Chain,
    lag_source: str,
    choices: list[tuple[np.ndarray, np.ndarray]],
) -> tuple[dict[str, Estimate], list[float], int, np.ndarray]:
    """To, eta and eta To^2 with 95 % intervals from these standard uncertainties (in ln):

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
    * ``choices``, each (down, up) in ln: how far the estimates move under another plausible
      choice the data cannot rule out, a bound taken as a rectangular distribution, a / sqrt(3)
      (GUM 4.3.7), on each side: the angle path's bandwidths the residual cannot tell from the
      best (``PathScan.envelope``, ``PATH_TOLERANCE``); a fitted lag against the data sheet's
      (``analyze_file``); the path's content above its bandwidth taken from the drive
      (``_drive_choice``).

    The spread between amplitudes holds the cycles' noise as well as the model's departure
    (each amplitude's cycles are noisy), so the two first terms are not added: the larger is
    taken (as a Birge-ratio or random-effects analysis does: a spread between groups no larger
    than within them reveals no error of the model). That one and the choices' add in
    quadrature, and the half-width is Student's t at the Welch-Satterthwaite degrees of freedom
    (GUM G.4) times their sum. Over 180 rigs of ``bench/hysteresis_coverage.py`` this covered
    To 175 and eta 169 times (docs/procedures/hysteresis.md); three 95 % half-widths added in
    quadrature, with the plain jackknife, had covered To 100 of the first 100.
    A fitted lag (``lag_source`` "fitted") is fitted again in every replicate, so its error
    is in both terms. Also returned: the relative standard errors (To, eta, stiffness; the
    cycles'), the cycles' degrees of freedom and the replicates' lags."""
    values = {
        "To_Nm": fit.To_Nm,
        "eta_per_Nm": fit.eta_per_Nm,
        "stiffness_Nm_per_rad": fit.stiffness_Nm_per_rad,
    }
    G = min(s.n_cycles for s in chain.segments)
    if G < 2:
        return (
            {
                k: Estimate(
                    v,
                    math.nan,
                    math.nan,
                    False,
                    f"{G} cycle per amplitude is too few for an interval",
                )
                for k, v in values.items()
            },
            [math.nan] * 3,
            max(0, G - 1),
            np.array([chain.lag_s]),
        )

    def with_stiffness(ln: np.ndarray) -> np.ndarray:
        return np.column_stack(
            [ln[:, 0], ln[:, 1], 2 * ln[:, 0] + ln[:, 1]]
        )  # ln k = 2 ln To + ln eta

    # the replicates are independent fits (their compiled kernels release the GIL): side by side
    with ThreadPoolExecutor(max_workers=max(1, min(analysis_threads(), G))) as pool:
        # G x (lag, ln To, ln eta)
        reps = np.array(list(pool.map(lambda j: chain(j, fit), range(G))))
        M = len(chain.seg_a)
        amps = list(pool.map(lambda j: chain.without_amplitude(j, fit), range(M))) if M >= 3 else []
    lnc = with_stiffness(reps[:, 1:])
    se = np.sqrt((G - 1) / G * np.sum((lnc - lnc.mean(axis=0)) ** 2, axis=0))
    if M >= 3:
        ln_full = with_stiffness(np.log([[fit.To_Nm, fit.eta_per_Nm]]))[0]
        lna = with_stiffness(np.array(amps))
        h = np.asarray(fit.leverage, dtype=float)
        w = (
            1.0 - h
            if h.shape == (M, 3) and np.all(np.isfinite(h))
            else np.full((M, 3), (M - 1) / M)
        )
        se_amp = np.sqrt(np.sum(w * (lna - ln_full) ** 2, axis=0))
    else:
        log.warning(
            "%d amplitude(s): too few to judge the model by; the intervals hold the cycles' noise only",
            M,
        )
        se_amp = np.zeros(3)
    out: dict[str, Estimate] = {}
    for i, (key, v) in enumerate(values.items()):
        # the amplitudes' spread holds their noise too: the larger of the two, not their sum
        noise = (float(se[i]), G - 1) if se[i] >= se_amp[i] else (float(se_amp[i]), M - 1)
        # each choice a rectangular bound on its side: a / sqrt(3) (GUM 4.3.7)
        lo, hi = (
            v
            * math.exp(
                sign
                * _half_width([noise, *((c[side][i] / math.sqrt(3), math.inf) for c in choices)])
            )
            for sign, side in ((-1, 0), (1, 1))
        )
        # To and eta are told apart by the ladder reaching both regimes (the procedure's limits
        # on eta To theta_o, and ``_applicable``), not by their correlation: each is judged by
        # its own interval
        out[key] = judged(v, lo, hi)
    log.info("jackknife over %d cycle groups: lags %s ms", G, np.round(reps[:, 0] * 1e3, 3))
    return out, [float(x) for x in se], G - 1, reps[:, 0]
