"""The earth-rate report: the fit table, the stations and the fit plot. The procedure is
``procedures.calibrations.earth_rate``; the fits (``ChannelFit``) are
``procedures.analysis.earth_rate``."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from daq.plots import new_figure, save_figure
from drivers.calibration import GYRO_CHANNELS
from procedures.analysis.earth_rate import ChannelFit
from procedures.reports.report import fmt


def plot_fits(path: Path, fits: dict[str, ChannelFit]) -> None:
    fig, axes = new_figure(2, 2, figsize=(10, 7))
    for ax, (ch, f) in zip(axes.flat, fits.items()):
        order = np.argsort(f.x_deg)
        ax.plot(f.x_deg[order], f.volts[order], "o", label="settled mean")
        ax.plot(f.x_deg[order], f.predicted[order], "-", label="fit")
        ax.set_title(f"{ch}: K_TO {f.kto_urad_per_s_per_V:.4g} ± {f.kto_se:.2g} urad/s/V")
        ax.set_xlabel(f"table {f.swept} angle (deg)")
        ax.set_ylabel(f"torq_{ch.lower()} (V)")
        ax.grid(True, alpha=0.4)
        ax.legend(fontsize=8)
    save_figure(fig, path)


def markdown(fits: dict[str, ChannelFit], stations: list[dict], names: Iterable[tuple[str, float, float, float]]) -> str:
    """The fit table and the stations (``names``: the procedure's (name, tilt, spindle,
    averaging time) per station, in the order of ``stations``)."""
    lines = ["## Fit", "", "| channel | K_TO (urad/s/V) | drift (urad/s) | psi0 (deg) | residual rms (mV) | swept |",
             "|---|---|---|---|---|---|"]
    for ch, f in fits.items():
        psi0 = "-" if f.psi0_deg is None else f"{f.psi0_deg:.4f} ± {f.psi0_se:.4f}"
        lines.append(f"| {ch} | {f.kto_urad_per_s_per_V:.5g} ± {f.kto_se:.2g} | {f.drift_urad_per_s:.4g} ± "
                     f"{f.drift_se:.2g} | {psi0} | {f.residual_rms_V * 1e3:.3f} | {f.swept} |")
    lines += ["", "Each fit has a term linear in the stations' visiting order as well, so a slow drift trend over the run "
              "does not bias the scale factor.", "",
              "Z is the spindle axis, so its rate does not change with the spindle angle; it was calibrated "
              "with the spindle at 90 deg and the table tilted (module docstring).", "",
              "## Stations", "", "| station | tilt | spindle | settled after (s) | " +
              " | ".join(f"torq {c} (V)" for c in GYRO_CHANNELS) + " |", "|---|---|---|---|" + "---|" * 4]
    for (name, *_), s in zip(names, stations):
        lines.append(f"| {name} | {fmt(s['tilt'])} | {fmt(s['spindle'])} | {s['settle_s']} | "
                     + " | ".join(f"{s['V'][c]:+.5f}" for c in GYRO_CHANNELS) + " |")
    return "\n".join(lines)
