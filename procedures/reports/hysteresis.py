"""The hysteresis report: the torque-angle loops, the describing function, the time history,
the angle-path scan (thesis Figs. 50-57) and the Markdown summary, for the ``hysteresis``
procedure's report (``procedures.calibrations.hysteresis``) and ``fbs analyze hysteresis --out``.
The numbers (``HysteresisResult``) are ``procedures.analysis.hysteresis``."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.ticker import ScalarFormatter

from daq.plots import new_figure, save_figure
from procedures.analysis import dahl
from procedures.analysis.hysteresis import HysteresisResult

#: where the instrument constants came from (``HysteresisResult.calibration_source``), in words
CAL_SOURCES = {
    "file": "the run's /meta/calibration",
    "given": "the rig's data sheet",
    "defaults": "the data sheet's defaults (the file recorded none)",
}


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
        ax.plot(
            th,
            1e3 * np.append(lp.torque_Nm, lp.torque_Nm[0]),
            ".",
            ms=2.5,
            label="measured (averaged)",
        )
        ax.plot(
            th,
            1e3 * np.append(lp.model_Nm, lp.model_Nm[0]),
            "-",
            lw=1.2,
            label="Dahl fit (eq. 5.2)",
        )
        ax.set_title(f"{lp.amplitude_urad:.3g} urad, {lp.n_cycles} cycles", fontsize=9)
        ax.set_xlabel("angle (urad)", fontsize=8)
        ax.set_ylabel("bearing torque (mN m)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.4)
    axes.flat[0].legend(fontsize=7, loc="upper left")
    fig.suptitle(
        f"{res.axis} gimbal bearing: torque against angle at {res.frequency_hz:.3g} Hz "
        f"(To {res.To_Nm * 1e3:.3g} mN m, eta {res.eta_per_Nm:.3g} /N m)",
        fontsize=10,
    )
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
    fig.suptitle(
        f"{res.axis} bearing: sinusoidal-input describing function (stiffness eta To^2 = {k:.4g} N m/rad)",
        fontsize=10,
    )
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


def _lag_text(res: HysteresisResult) -> str:
    if res.lag is not None:
        lines = ", ".join(
            f"{f:.4g} Hz: {1e3 * x:.3g} ± {1e3 * e:.2g} ms"
            for f, x, e in zip(res.lag.frequencies_hz, res.lag.lags_s, res.lag.lag_se_s)
        )
        return (
            f"angle lag behind the power-amplifier input {res.angle_lag_s * 1e3:.3g} ± "
            f"{res.angle_lag_se_s * 1e3:.2g} ms, measured at the command's DAC lines ({lines}) and taken out"
        )
    if res.lag_source == "fitted":
        return (
            f"angle lag behind the power-amplifier input {res.angle_lag_s * 1e3:.3g} ± "
            f"{res.angle_lag_se_s * 1e3:.2g} ms, fitted with To and eta (the command carries no line) and taken out"
        )
    if res.lag_source == "given":
        return f"angle lag {res.angle_lag_s * 1e3:.3g} ms, given (not measured), taken out"
    return "angle lag not measured: the angle is used as recorded (its lag biases eta and the stiffness high)"


def markdown(res: HysteresisResult) -> str:
    lines = [
        "## Bearing friction (Dahl model, eq. 5.2)",
        "",
        f"Axis {res.axis}, drive {res.frequency_hz:.4g} Hz; torque band {res.torque_cutoff_hz:.3g} Hz, "
        f"angle path low-passed at {res.path_cutoff_hz:.3g} Hz (least residual of "
        f"{len(res.scan.cutoff_hz)} tried); instrument constants: {CAL_SOURCES[res.calibration_source]}.",
        "",
        *[
            f"- {label} = {e.value:.5g} {unit}, 95 % interval [{e.lo:.5g}, {e.hi:.5g}]"
            + ("" if e.resolved else f" — **not resolved**: {e.why}")
            for key, label, unit in (
                ("To_Nm", "To", "N m"),
                ("eta_per_Nm", "eta", "(N m)^-1"),
                ("stiffness_Nm_per_rad", "stiffness eta To^2", "N m/rad"),
            )
            for e in (res.estimates[key],)
            if key in res.estimates
        ],
        f"- {_lag_text(res)}",
        f"- correlation of the To and eta estimates {res.correlation:+.3f}; the intervals are cluster-robust "
        f"over the {sum(lp.n_cycles for lp in res.loops)} analysed cycles (Student t, {res.dof} degrees of "
        f"freedom) with the lag's error carried in; not the model's or the data sheet's errors",
        f"- fit residual rms {res.residual_rms_Nm * 1e3:.4g} mN m = {100 * res.relative_residual:.3g} % of the "
        f"largest loop's torque half-range",
        "",
    ]
    lines += [
        "| amplitude (urad) | eta To theta_o | cycles | torque p-p (mN m) | describing fn. gain / k "
        "(measured, eq. 5.12) | phase deg (measured, eq. 5.12) | residual rms (mN m) |",
        "|---|---|---|---|---|---|---|",
    ]
    k = res.stiffness_Nm_per_rad
    for lp in res.loops:
        m, d = lp.describing_Nm_per_rad / k, lp.model_describing_Nm_per_rad / k
        lines.append(
            f"| {lp.amplitude_urad:.4g} | {res.theta_o_bar(lp):.3g} | {lp.n_cycles} | "
            f"{np.ptp(lp.torque_Nm) * 1e3:.4g} | {abs(m):.3f}, {abs(d):.3f} | "
            f"{math.degrees(np.angle(m)):.1f}, {math.degrees(np.angle(d)):.1f} | "
            f"{lp.residual_rms_Nm * 1e3:.3g} |"
        )
    if res.warnings:
        lines += [""] + [f"Warning: {w}" for w in res.warnings]
    return "\n".join(lines) + "\n"
