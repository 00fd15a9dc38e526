"""``hysteresis``: the gimbal bearings' torque-angle sweep (thesis Ch. V F, Figs. 50-57).

In Mode 3 the autocollimator bias gamma_c, summed into the control channel's output, moves the
platform to about -gamma_c / (control scale): a sinusoidal bias at ``frequency_hz`` (0.4 Hz,
as Fig. 51) is stepped through a ladder of amplitudes from large (Coulomb friction) to small
(a spring). The bias is a DAC: it is updated ``updates_per_cycle`` times a cycle, between ADC
blocks, so every value applied is on the file's time base (channel ``cmd_<axis>``).

The analysis (``analyze_file``, also ``fbs analyze hysteresis FILE --axis X``) reads only the
file: the angle from the instrumentation channel, the bearing torque from the power-amplifier
input with the platform's inertial and viscous torques removed (``dahl.bearing_torque``), the
cycles of constant amplitude from the command channel; Dahl's To and eta are fitted by
integrating eq. 5.2 along the measured angle (``dahl.fit_dahl_path``). It reports the loops
(Figs. 51, 53, 54), the describing function (eq. 5.12, Fig. 57) and the small-motion stiffness
eta To^2. Every instrument constant comes from the rig's data sheet (``RigCalibration``: the
run's own ``/meta/calibration`` for a file); none is a procedure constant.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.ticker import ScalarFormatter

from daq.reader import RunFile
from daq.runfile import RunFileError
from drivers.calibration import AXES, AutocollimatorConstants, PlatformConstants, RigCalibration
from procedures.analysis import dahl
from procedures.reports.plotting import new_figure, save_figure
from procedures.rigsetup import bring_to_mode3
from procedures.runner import Analysis, Context, Figure, Measurement, Procedure, Step

log = logging.getLogger(__name__)

URAD = 1e-6
JSON_KEYS = ("To_Nm", "eta_per_Nm", "stiffness_Nm_per_rad", "file")
#: the axes with a primary (two-axis) autocollimator, hence an instrumentation channel (DESIGN.md section 5)
AC_AXES = ("X", "Y")
CAL_SOURCES = {"file": "the run's /meta/calibration", "given": "the rig's data sheet",
               "defaults": "the data sheet's defaults (the file recorded none)"}


# ---------------------------------------------------------------------------- parameters
@dataclass
class HysteresisParams:
    axis: str = "X"
    frequency_hz: float = 0.4
    #: the ladder, large to small (a large first loop wipes out the bearing's earlier state)
    amplitudes_urad: list[float] = field(default_factory=lambda: [500.0, 250.0, 100.0, 50.0, 25.0, 10.0, 5.0])
    #: analysed cycles per amplitude, after ``settle_cycles`` left out
    cycles: int = 6
    settle_cycles: int = 1
    #: bias DAC updates per cycle; rate_hz / (frequency_hz * updates_per_cycle) must be whole samples
    updates_per_cycle: int = 100
    rate_hz: float = 400.0
    #: how far the instrumentation angle lags the power-amplifier input (its filters and the
    #: motor's L/R), if the data sheet says; 0 leaves the angle as recorded
    angle_lag_ms: float = 0.0
    #: quality limits: fit residual rms / largest loop's torque half-range; relative standard errors
    max_relative_residual: float = 0.1
    max_relative_se: float = 0.1

    def __post_init__(self) -> None:
        self.axis = str(self.axis).upper()
        if self.axis not in AC_AXES:
            raise ValueError(f"hysteresis: axis {self.axis!r} has no instrumentation autocollimator channel "
                             f"(X or Y)")
        self.amplitudes_urad = [float(a) for a in self.amplitudes_urad]
        if not self.amplitudes_urad or any(not (a > 0 and math.isfinite(a)) for a in self.amplitudes_urad):
            raise ValueError(f"hysteresis: amplitudes_urad {self.amplitudes_urad} must be a non-empty list of "
                             f"positive numbers")
        if not (self.frequency_hz > 0 and self.rate_hz > 0):
            raise ValueError("hysteresis: frequency_hz and rate_hz must be > 0")
        if not (0.0 <= self.angle_lag_ms < 1e3 / self.rate_hz * 20):
            raise ValueError(f"hysteresis: angle_lag_ms = {self.angle_lag_ms} must be >= 0 and a few samples at most")
        if int(self.cycles) < 2 or int(self.settle_cycles) < 0:
            raise ValueError(f"hysteresis: cycles = {self.cycles} must be >= 2 and settle_cycles = "
                             f"{self.settle_cycles} >= 0")
        if int(self.updates_per_cycle) < 8:
            raise ValueError(f"hysteresis: updates_per_cycle = {self.updates_per_cycle} is too coarse a sine (>= 8)")
        per_update = self.rate_hz / (self.frequency_hz * self.updates_per_cycle)
        if abs(per_update - round(per_update)) > 1e-9 or round(per_update) < 1:
            raise ValueError(f"hysteresis: rate_hz / (frequency_hz * updates_per_cycle) = {per_update:g} samples "
                             f"per bias update must be a whole number >= 1")


# ---------------------------------------------------------------------------- the analysis
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

    def values(self) -> dict[str, Any]:
        """The summary keys of DESIGN.md section 7."""
        return {"To_Nm": self.To_Nm, "eta_per_Nm": self.eta_per_Nm,
                "stiffness_Nm_per_rad": self.stiffness_Nm_per_rad, "file": self.file}

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
        return RigCalibration(**kw)
    except (TypeError, AttributeError) as exc:
        raise ValueError(f"/meta/calibration is not a rig calibration ({exc})") from None


def _make(cls: type, value: Any) -> Any:
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in dict(value).items() if k in names})


def analyze_file(path: str | Path, axis: str = "X", calibration: RigCalibration | None = None, *,
                 settle_cycles: int = 1, angle_lag_s: float = 0.0, bins: int = 200) -> HysteresisResult:
    """Dahl's To and eta, the loops and the describing function from any "fbs-run" file with
    ``cmd_<a>``, ``ac_<a>_inst`` and ``pa_<a>`` channels recorded during a sinusoidal command
    at one frequency and a ladder of amplitudes (``settle_cycles`` at each new amplitude are
    left out). ``calibration`` defaults to the file's ``/meta/calibration``, else the data
    sheet's defaults (with a warning). ``angle_lag_s``: the recorded angle is advanced by this
    much (the instrumentation channel's lag behind the power-amplifier input, if known).
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
    cmd, inst, pa = data
    if len(cmd) < 16:
        raise ValueError(f"{path}: {len(cmd)} samples are too few for an analysis")
    freq = dahl.command_frequency(np.nan_to_num(cmd), fs)
    segments = dahl.find_segments(np.nan_to_num(cmd), fs, freq, settle_cycles=settle_cycles)
    if not segments:
        raise ValueError(f"{path}: {names[0]} has no run of at least {2 + settle_cycles} cycles at one amplitude "
                         f"(a sinusoid near {freq:.4g} Hz); too short, or not a hysteresis sweep")
    a0 = min(s.lead_start for s in segments)
    b0 = max(s.stop for s in segments)
    for name, x in zip(names, data):
        bad = int(np.count_nonzero(~np.isfinite(x[a0:b0])))
        if bad:
            raise ValueError(f"{path}: {name} has {bad} lost (NaN) samples in the cycles to analyse "
                             f"({a0 / fs:.2f}..{b0 / fs:.2f} s)")
    # the torque band: the fundamental and its harmonics well into the loops' corners
    fc = min(12.5 * freq, 0.2 * fs)
    if not (math.isfinite(angle_lag_s) and 0.0 <= angle_lag_s * fs < 20):
        raise ValueError(f"angle lag {angle_lag_s * 1e3:g} ms must be >= 0 and under 20 samples")
    theta = dahl.shift(inst / (ac.inst_mV_per_urad * 1e-3) * URAD, fs, angle_lag_s)
    theta_f = dahl.lowpass(theta, fs, fc)
    torque = dahl.bearing_torque(dahl.lowpass(pa, fs, fc), theta_f, fs, torque_per_pa_Nm_per_V=plat.torque_per_pa_V,
                                 viscous_Nms=plat.viscous_Nms, inertia_kg_m2=plat.inertia_kg_m2)
    top = min(10.0 * fc, 0.35 * fs)
    cutoffs = [c for c in 1.25 * fc * 1.25 ** np.arange(20) if c <= top] or [fc]
    step = max(1, int(fs / (8.0 * fc)))
    fit, scan = dahl.fit_dahl_path(theta, torque, segments, fs, smooth_hz=fc, cutoffs_hz=cutoffs, step=step,
                                   independent_every=max(1, int(fs / (2.0 * fc))))
    if fit.path_cutoff_hz in (cutoffs[0], cutoffs[-1]) and len(cutoffs) > 1:
        msg = (f"the angle-path bandwidth that fits best, {fit.path_cutoff_hz:.3g} Hz, is at the end of the "
               f"range tried ({cutoffs[0]:.3g}..{cutoffs[-1]:.3g} Hz)")
        log.warning(msg)
        warnings.append(msg)
    model = np.full(len(theta), np.nan)
    model[fit.start:fit.stop] = fit.model_Nm
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
    return HysteresisResult(str(path), a, freq, fit.To_Nm, fit.eta_per_Nm, k, fit.To_se_Nm, fit.eta_se_per_Nm,
                            fit.stiffness_se_Nm_per_rad, fit.correlation, fc, float(fit.path_cutoff_hz), scan, loops,
                            fit.residual_rms_total_Nm, relative, source, fs, history, warnings)


# ---------------------------------------------------------------------------- figures
def plot_loops(path: str | Path, res: HysteresisResult) -> Path:
    """Torque against angle at each amplitude (Figs. 51, 53, 54): measured and fitted."""
    n = len(res.loops)
    ncols = min(4, n)
    nrows = int(math.ceil(n / ncols))
    fig, axes = new_figure(nrows, ncols, figsize=(3.6 * ncols, 3.2 * nrows))
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    for ax, lp in zip(axes.flat, res.loops):
        th = np.append(lp.theta_urad, lp.theta_urad[0])
        ax.plot(th, 1e3 * np.append(lp.torque_Nm, lp.torque_Nm[0]), ".", ms=2.5, label="measured (averaged)")
        ax.plot(th, 1e3 * np.append(lp.model_Nm, lp.model_Nm[0]), "-", lw=1.2, label="Dahl fit (eq. 5.2)")
        ax.set_title(f"{lp.amplitude_urad:.3g} urad, {lp.n_cycles} cycles", fontsize=9)
        ax.set_xlabel("angle (urad)", fontsize=8)
        ax.set_ylabel("bearing torque (mN m)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.4)
    axes.flat[0].legend(fontsize=7, loc="upper left")
    fig.suptitle(f"{res.axis} gimbal bearing: torque against angle at {res.frequency_hz:.3g} Hz "
                 f"(To {res.To_Nm * 1e3:.3g} mN m, eta {res.eta_per_Nm:.3g} /N m)", fontsize=10)
    return save_figure(fig, path)


def plot_describing_function(path: str | Path, res: HysteresisResult) -> Path:
    """Gain and phase of the describing function against eta To theta_o (eq. 5.12, Fig. 57)."""
    fig, axes = new_figure(1, 2, figsize=(10.0, 4.2))
    k = res.stiffness_Nm_per_rad
    xs = np.array([res.theta_o_bar(lp) for lp in res.loops])
    meas = np.array([lp.describing_Nm_per_rad for lp in res.loops]) / k
    lo, hi = min(xs.min() / 3, 1e-2), max(xs.max() * 3, 1e2)
    grid = np.geomspace(lo, hi, 300)
    curve = np.asarray(dahl.describing_function(grid))
    ax1, ax2 = axes.flat
    ax1.loglog(grid, np.abs(curve), "-", label="eq. 5.12")
    ax1.loglog(xs, np.abs(meas), "o", label="measured")
    ax1.loglog(grid, 4 / (np.pi * grid), ":", lw=0.8, label="Coulomb, 4/(pi x)")
    ax1.set_ylim(min(np.abs(curve).min(), np.abs(meas).min()) / 2, 2.0)
    ax1.set_xlabel("eta To theta_o")
    ax1.set_ylabel("|T_D / theta_o| / (eta To^2)")
    ax2.semilogx(grid, np.degrees(np.angle(curve)), "-", label="eq. 5.12")
    ax2.semilogx(xs, np.degrees(np.angle(meas)), "o", label="measured")
    ax2.set_xlabel("eta To theta_o")
    ax2.set_ylabel("phase (deg, torque leading the angle)")
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.4)
        ax.legend(fontsize=8)
    fig.suptitle(f"{res.axis} bearing: sinusoidal-input describing function (stiffness eta To^2 = {k:.4g} N m/rad)",
                 fontsize=10)
    return save_figure(fig, path)


def plot_history(path: str | Path, res: HysteresisResult) -> Path:
    """Angle and torque against time over the largest loop (Fig. 50)."""
    h = res.history
    fig, axes = new_figure(2, 1, figsize=(9.0, 5.5))
    ax1, ax2 = axes.flat
    ax1.plot(h["t_s"], h["theta_urad"], "-")
    ax1.set_ylabel("angle (urad)")
    ax2.plot(h["t_s"], 1e3 * h["torque_Nm"], "-", label="measured")
    ax2.plot(h["t_s"], 1e3 * h["model_Nm"], "--", label="Dahl fit")
    ax2.set_ylabel("bearing torque (mN m)")
    ax2.set_xlabel("file time (s)")
    ax2.legend(fontsize=8)
    for ax in (ax1, ax2):
        ax.grid(True, alpha=0.4)
    fig.suptitle(f"{res.axis} bearing: time history at the largest amplitude", fontsize=10)
    return save_figure(fig, path)


def plot_scan(path: str | Path, res: HysteresisResult) -> Path:
    """Residual, To and eta against the bandwidth of the angle path the bearing is taken to follow."""
    sc = res.scan
    fig, axes = new_figure(1, 2, figsize=(10.0, 3.8))
    ax1, ax2 = axes.flat
    ax1.plot(sc.cutoff_hz, 1e3 * np.array(sc.residual_rms_Nm), "o-")
    ax1.axvline(sc.cutoff_hz[sc.best], color="k", lw=0.8, ls=":")
    ax1.set_xlabel("angle-path low-pass (Hz)")
    ax1.set_ylabel("fit residual rms (mN m)")
    ax2.plot(sc.cutoff_hz, np.array(sc.To_Nm) / res.To_Nm, "o-", label="To / chosen")
    ax2.plot(sc.cutoff_hz, np.array(sc.eta_per_Nm) / res.eta_per_Nm, "s-", label="eta / chosen")
    ax2.axvline(sc.cutoff_hz[sc.best], color="k", lw=0.8, ls=":")
    ax2.set_xlabel("angle-path low-pass (Hz)")
    ax2.legend(fontsize=8)
    for ax in (ax1, ax2):
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(ScalarFormatter())
        ax.xaxis.set_minor_formatter(ScalarFormatter())
        ax.tick_params(axis="x", which="minor", labelsize=7)
        ax.grid(True, which="both", alpha=0.4)
    return save_figure(fig, path)


def markdown(res: HysteresisResult) -> str:
    lines = ["## Bearing friction (Dahl model, eq. 5.2)", "",
             f"Axis {res.axis}, drive {res.frequency_hz:.4g} Hz; torque band {res.torque_cutoff_hz:.3g} Hz, "
             f"angle path low-passed at {res.path_cutoff_hz:.3g} Hz (least residual of "
             f"{len(res.scan.cutoff_hz)} tried); instrument constants: {CAL_SOURCES[res.calibration_source]}.", "",
             f"- To = {res.To_Nm:.5g} ± {res.To_se_Nm:.2g} N m",
             f"- eta = {res.eta_per_Nm:.5g} ± {res.eta_se_per_Nm:.2g} (N m)^-1",
             f"- stiffness eta To^2 = {res.stiffness_Nm_per_rad:.5g} ± {res.stiffness_se_Nm_per_rad:.2g} N m/rad",
             f"- correlation of the To and eta estimates {res.correlation:+.3f}; the errors are statistical "
             f"(residual noise), not the model's or the data sheet's",
             f"- fit residual rms {res.residual_rms_Nm * 1e3:.4g} mN m = {100 * res.relative_residual:.3g} % of the "
             f"largest loop's torque half-range", ""]
    lines += ["| amplitude (urad) | eta To theta_o | cycles | torque p-p (mN m) | describing fn. gain / k "
              "(measured, eq. 5.12) | phase deg (measured, eq. 5.12) | residual rms (mN m) |",
              "|---|---|---|---|---|---|---|"]
    k = res.stiffness_Nm_per_rad
    for lp in res.loops:
        m, d = lp.describing_Nm_per_rad / k, lp.model_describing_Nm_per_rad / k
        lines.append(f"| {lp.amplitude_urad:.4g} | {res.theta_o_bar(lp):.3g} | {lp.n_cycles} | "
                     f"{np.ptp(lp.torque_Nm) * 1e3:.4g} | {abs(m):.3f}, {abs(d):.3f} | "
                     f"{math.degrees(np.angle(m)):.1f}, {math.degrees(np.angle(d)):.1f} | "
                     f"{lp.residual_rms_Nm * 1e3:.3g} |")
    if res.warnings:
        lines += [""] + [f"Warning: {w}" for w in res.warnings]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------- the procedure
#: the name the module's functions and tests use
Params = HysteresisParams


class Hysteresis(Procedure[HysteresisParams]):
    name = "hysteresis"
    title = "Gimbal bearing torque-angle sweep: Dahl's To and eta (Ch. V F)"
    json_keys = JSON_KEYS
    Params = HysteresisParams
    mode = 3

    def __init__(self, params: HysteresisParams | None = None, **kw) -> None:
        super().__init__(params, **kw)
        p = self.params
        self.axis = p.axis
        self.rate_hz = p.rate_hz
        #: one ADC block per bias update: the DAC changes between blocks
        self.block_s = 1.0 / (p.frequency_hz * p.updates_per_cycle)
        # The torque proxy is millivolts (To ~ 2-4 mV at the amplifier input): +-0.2 V full
        # scale puts 6 uV in a count instead of 0.3 mV at +-10 V.
        self.ranges_V = {f"pa_{p.axis.lower()}": 0.2}

    def channels(self) -> tuple[str, ...]:
        a = self.axis.lower()
        return (f"cmd_{a}", f"ac_{a}_inst", f"pa_{a}", f"ac_{a}_ctl")

    def plan(self) -> list[Step]:
        p = self.params
        per = (p.settle_cycles + p.cycles) / p.frequency_hz
        # The sweep steps run again on --resume (setup=True) rather than being taken over: the
        # fit integrates eq. 5.2 along one continuous recording of the whole ladder, and the
        # bearing's state after an interruption is not the one the earlier steps left.
        sweeps = [Step(f"{amp:g} urad", lambda c, amp=amp: self.sweep(c, amp), expected_s=per, setup=True)
                  for amp in p.amplitudes_urad]
        return [Step("mode 3", bring_to_mode3, expected_s=300.0, setup=True), *sweeps,
                Step("bias off", self.bias_off, expected_s=1.0 / p.frequency_hz, setup=True)]

    def sweep(self, ctx: Context, amplitude_urad: float) -> dict:
        """``settle_cycles + cycles`` cycles of the sinusoidal bias: theta ~ amplitude sin(w t)."""
        p = self.params
        volts_per_urad = ctx.rig.calibration.autocollimator[self.axis].control_mV_per_urad * 1e-3
        amp_V = amplitude_urad * volts_per_urad
        n = (p.settle_cycles + p.cycles) * p.updates_per_cycle
        t0 = ctx.time_s
        for k in range(n):
            # mid-interval value of the sine; the platform goes to -gamma_c / scale
            ctx.rig.set_ac_bias_V(self.axis, -amp_V * math.sin(2 * math.pi * (k + 0.5) / p.updates_per_cycle))
            ctx.acquire(self.block_s, keep=False, chunk_s=self.block_s)
        return {"amplitude_urad": amplitude_urad, "bias_amplitude_V": round(amp_V, 6),
                "t_s": [round(t0, 4), round(ctx.time_s, 4)], "cycles": p.settle_cycles + p.cycles}

    def bias_off(self, ctx: Context) -> dict:
        ctx.rig.set_ac_bias_V(self.axis, 0.0)
        ctx.acquire(1.0 / self.params.frequency_hz, keep=False)
        return {"bias_V": 0.0}

    def analyze(self, ctx: Context) -> Analysis:
        p = self.params
        res = analyze_file(ctx.path, self.axis, ctx.rig.calibration, settle_cycles=p.settle_cycles,
                           angle_lag_s=p.angle_lag_ms * 1e-3)
        xs = [res.theta_o_bar(lp) for lp in res.loops]
        ms = [Measurement("To", res.To_Nm, "N m", lo=0.0, stderr=res.To_se_Nm,
                          note="running (Coulomb) friction torque, eq. 5.2"),
              Measurement("eta", res.eta_per_Nm, "1/(N m)", lo=0.0, stderr=res.eta_se_per_Nm),
              Measurement("stiffness eta To^2", res.stiffness_Nm_per_rad, "N m/rad", lo=0.0,
                          stderr=res.stiffness_se_Nm_per_rad),
              Measurement("To relative standard error", res.To_se_Nm / res.To_Nm, "", hi=p.max_relative_se),
              Measurement("eta relative standard error", res.eta_se_per_Nm / res.eta_per_Nm, "",
                          hi=p.max_relative_se),
              Measurement("fit residual rms / largest loop torque half-range", res.relative_residual, "",
                          hi=p.max_relative_residual),
              # the ladder must reach both regimes, or To and eta are not separable
              Measurement("largest eta To theta_o (Coulomb regime)", max(xs), "", lo=2.0),
              Measurement("smallest eta To theta_o (spring regime)", min(xs), "", hi=1.0),
              Measurement("angle-path low-pass", res.path_cutoff_hz, "Hz")]
        figures = [Figure("loops", "Bearing torque against angle at each amplitude: synchronous averages and the "
                          "Dahl fit (cf. Figs. 51, 53, 54)", lambda path: plot_loops(path, res)),
                   Figure("describing-function", "Describing function, measured first harmonics and eq. 5.12 "
                          "(cf. Fig. 57)", lambda path: plot_describing_function(path, res)),
                   Figure("history", "Angle and torque over the largest loop (cf. Fig. 50)",
                          lambda path: plot_history(path, res)),
                   Figure("path-scan", "Fit residual, To and eta against the angle path's bandwidth",
                          lambda path: plot_scan(path, res))]
        return Analysis(res.values(), ms, figures, markdown(res))


PROCEDURE = Hysteresis
