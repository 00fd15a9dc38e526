"""The earth-rate report: the fit table, the stations and the fit plot. The procedure is
``procedures.calibrations.earth_rate``; the fits (``ChannelFit``) are
``procedures.analysis.earth_rate``."""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from daq.plots import new_figure, save_figure
from drivers.rig_datasheet import GYRO_CHANNELS
from procedures.analysis.earth_rate import ChannelFit, Station
from procedures.analysis.intervals import Estimate
from procedures.reports.procedure_report import fmt


def plot_fits(path: Path, fits: dict[str, ChannelFit]) -> None:
    fig, axes = new_figure(2, 2, figsize=(10, 7))
    for ax, (ch, f) in zip(axes.flat, fits.items()):
        k = np.arange(len(f.volts))
        ax.plot(k, f.volts, "o", label="settled mean")
        ax.plot(k, f.predicted, "-", label="fit")
        ax.set_title(f"{ch}: K_TO {f.kto.value:.5g} [{f.kto.lo:.5g}, {f.kto.hi:.5g}] urad/s/V")
        ax.set_xlabel("station (visiting order; tilt and spindle in the report's table)")
        ax.set_ylabel(f"torq_{ch.lower()} (V)")
        ax.grid(True, alpha=0.4)
        ax.legend(fontsize=8)
    save_figure(fig, path)


def _cell(e: Estimate, digits: int = 4) -> str:
    if not math.isfinite(e.lo):
        return "not resolved (not varied)"
    iv = f"[{e.lo:.{digits}g}, {e.hi:.{digits}g}]"
    return f"{e.value:.{digits}g} {iv}" if e.resolved else f"not resolved {iv}"


def markdown(
    fits: dict[str, ChannelFit],
    stations: list[Station],
    names: Iterable[tuple[str, float, float, float]],
) -> str:
    """The fit table (every figure with its 95 % interval, unresolved ones marked) and the
    stations (``names``: the procedure's (name, tilt, spindle, averaging time) per station, in
    the order of ``stations``)."""
    lines = [
        "## Fit (95 % intervals)",
        "",
        "| channel | K_TO (urad/s/V) | fixed drift (urad/s) | g-drift x | g-drift y | g-drift z (urad/s/g) | "
        "psi0 (deg) | residual rms (mV) | restraint term on K_TO |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for ch, f in fits.items():
        psi0 = "-" if f.psi0_deg is None else f"{f.psi0_deg:.4f}"
        lines.append(
            f"| {ch} | {_cell(f.kto, 6)} | {_cell(f.drift)} | {_cell(f.g_drift['x'])} | "
            f"{_cell(f.g_drift['y'])} | {_cell(f.g_drift['z'])} | {psi0} | {f.residual_rms_V * 1e3:.3f} | "
            f"{f.restraint_correction * 100:+.3f} % |"
        )
    unresolved = [
        (ch, k, e.why) for ch, f in fits.items() for k, e in f.figures.items() if not e.resolved
    ]
    lines += [
        "",
        "Intervals: generalised least squares with station errors correlated from one station to the next "
        "(AR(1) in visiting order, its correlation a nuisance integrated out over its restricted "
        "likelihood), Student's t "
        "with the fit's residual degrees of freedom. A figure is *not resolved* when its interval is wider than "
        "its magnitude or its estimate correlates with another by more than 0.95.",
    ]
    if unresolved:
        lines += [
            "",
            "Not resolved: " + "; ".join(f"{ch} {k} ({why})" for ch, k, why in unresolved) + ".",
        ]
    lines += [
        "",
        "Each fit has a term linear in the stations' visiting order as well, so a slow drift trend over the "
        "run does not bias the rest. The restraint term is the standing pickoff's share of the balance, "
        "sigma / (h/k) (a proportional-only caging loop leaves a standing angle).",
        "",
        "## Stations",
        "",
        "| station | tilt | spindle | settled after (s) | "
        + " | ".join(f"torq {c} (V)" for c in GYRO_CHANNELS)
        + " |",
        "|---|---|---|---|" + "---|" * 4,
    ]
    for (name, *_), s in zip(names, stations):
        lines.append(
            f"| {name} | {fmt(s.tilt)} | {fmt(s.spindle)} | {s.settle_s} | "
            + " | ".join(f"{s.V[c]:+.5f}" for c in GYRO_CHANNELS)
            + " |"
        )
    return "\n".join(lines)
