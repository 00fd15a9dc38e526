"""The stopwatch report: the results table, the readings per ramp, and each channel's ramp plot
read back from the run file. The procedure is ``procedures.calibrations.stopwatch``; the
readings (``ChannelResult``) are ``procedures.analysis.stopwatch``."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from daq.plots import new_figure, save_figure
from daq.reader import RunFile
from procedures.analysis.intervals import Estimate
from procedures.analysis.stopwatch import ChannelResult, ChannelRun


def _interval(e: Estimate, fmt: str) -> str:
    # no interval (one repetition: no spread) is said so, never "[nan, nan]"
    nan = math.isnan(e.lo) or math.isnan(e.hi)
    span = "(no interval)" if nan else f"[{e.lo:{fmt}}, {e.hi:{fmt}}]"
    return f"{e.value:{fmt}} {span}" if e.resolved else f"not resolved {span}"


def markdown(
    per: dict[str, ChannelResult], kg: dict[str, Estimate], tau: dict[str, Estimate]
) -> str:
    lines = [
        "## Results",
        "",
        "| channel | K_g stopwatch (mV/urad) [95 %] | spread | up - down | K_g least squares | h/k fitted (s) [95 %] | "
        "restraint correction | residual null rate (urad/s) | K_TO used (urad/s/V) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for ch, r in per.items():
        lines.append(
            f"| {ch} | {_interval(kg[ch], '.4f')} | {100 * r.spread:.2f} % | {100 * r.asymmetry:+.2f} % | "
            f"{r.kg_ls:.4f} ± "
            f"{r.kg_ls_se:.4f} | {_interval(tau[ch], '.0f')} | {100 * r.correction:+.3f} % | "
            f"{r.null_rate_urad_per_s:+.4f} | "
            f"{r.kto:.4g} ({r.kto_from}) |"
        )
    nominal = [ch for ch, r in per.items() if r.kto_from == "nominal"]
    if nominal:
        lines += [
            "",
            f"**K_TO for {', '.join(nominal)} is the data sheet's nominal value**, not a measurement: "
            "run `fbs run earth-rate` first (same --out) for measured K_g.",
        ]
    lines += ["", "Readings per ramp (corrected / uncorrected, mV/urad):", ""]
    for ch, r in per.items():
        lines.append(
            f"- {ch}: " + ", ".join(f"{c:.4f} / {n:.4f}" for c, n in zip(r.readings, r.naive))
        )
    lines += [
        "",
        "The ramps run between levels symmetric about the null position, so the elastic restraint's "
        "effect is second order (x coth x, x = dt / 2 (h/k)); h/k is fitted from the whole open-loop record "
        "with the float partner's torquer as a regressor; it is shown with its interval but not reported as a "
        "figure (the fit also carries the partner's viscous coupling). K_g's interval is Student's t over the "
        "repetitions combined with the interval of the K_TO used.",
    ]
    return "\n".join(lines)


def plot_channel(path: Path, run: Path, ch: str, r: ChannelRun) -> None:
    """The channel's pickoff (with the two stopwatch levels) and torquer output from the loop's
    opening to the end of the ramps, read from the run file ``run``; ``r`` the step's result."""
    if r.t is None:
        raise ValueError(f"channel {ch}: its result has no times to plot")
    t0, _, t1 = r.t
    with RunFile(run) as rf:
        block = rf.slice_s(t0, t1, [f"gyro_{ch.lower()}", f"torq_{ch.lower()}"])
    fig, axes = new_figure(2, 1, figsize=(10, 6))
    data = block.data
    t = (block.start + np.arange(len(block))) / block.rate_hz
    axes[0, 0].plot(t, data[0], lw=0.5)
    for level in (r.vg0 - r.dVg / 2, r.vg0 + r.dVg / 2):
        axes[0, 0].axhline(level, color="k", ls="--", lw=0.8)
    axes[0, 0].set_ylabel(f"gyro_{ch.lower()} (V)")
    axes[1, 0].plot(t, data[1], lw=0.8)
    axes[1, 0].set_ylabel(f"torq_{ch.lower()} (V)")
    axes[1, 0].set_xlabel("file time (s)")
    for ax in axes[:, 0]:
        ax.grid(True, alpha=0.4)
    save_figure(fig, path)
