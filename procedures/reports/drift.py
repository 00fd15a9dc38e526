"""The drift report: the Allan table and its reading notes, the null stability, the pickoffs,
and the Allan and null-wander plots. The procedure is ``procedures.calibrations.drift``; the
numbers (``ChannelDrift``) are ``procedures.analysis.drift``."""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

import numpy as np

from daq.plots import new_figure, save_figure
from drivers.calibration import GYRO_CHANNELS
from procedures.analysis.drift import ChannelDrift, DriftSettings


class ReportSettings(DriftSettings, Protocol):
    """The parameters the report reads (the procedure's ``DriftParams`` has them)."""

    rate_hz: float


def hours(seconds: float) -> str:
    """A duration for a caption: hours from one hour up, else seconds."""
    return f"{seconds / 3600:.3g} h" if seconds >= 3600 else f"{seconds:.4g} s"


def markdown(res: dict[str, ChannelDrift], p: ReportSettings, kto: dict[str, float], kto_source: str, record_s: float,
             lost: int, total: int, pickoff: dict[str, tuple[float, float]], kg_measured: bool) -> str:
    nominal_note = ("" if "NOMINAL" not in kto_source else
                    "\n**K_TO: the rig's nominal data-sheet values were used** (no earth-rate result was given); "
                    "K_TO only scales the rates here, so every rate below scales with it.\n")
    lines = ["## Drift stability", "",
             f"Record: {hours(record_s)} of the torquer outputs in Mode 3 at {p.rate_hz:g} Hz "
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
              f"| channel | p-p over the record (urad/s) | record | {hours(p.null_span_s)} p-p (urad/s) | how |",
              "|---|---|---|---|---|"]
    for ch, r in res.items():
        n = r.null
        if n is None:
            lines.append(f"| {ch} | - | - | - | {'; '.join(r.problems)} |")
            continue
        how = ("measured" if n.measured_over_span else
               f"estimate: record p-p x {n.ratio:.3g}")
        lines.append(f"| {ch} | {n.peak_to_peak:.4g} | {hours(n.record_s)} ({n.n_averages} means) | "
                     f"{n.estimate:.4g} | {how} |")
    if any(r.null and not r.null.measured_over_span for r in res.values()):
        lines += ["", f"The {hours(p.null_span_s)} figure is an estimate: the record's peak-to-peak times the "
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


def plot_allan(path: Path, res: dict[str, ChannelDrift], p: DriftSettings) -> None:
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


def plot_null(path: Path, res: dict[str, ChannelDrift], p: DriftSettings) -> None:
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
