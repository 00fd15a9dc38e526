"""The drift report: the Allan table and its reading notes, the null stability, the pickoffs,
and the Allan and null-wander plots. The procedure is ``procedures.calibrations.drift``; the
numbers (``ChannelDrift``) are ``procedures.analysis.drift``."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Protocol

import numpy as np

from daq.plots import new_figure, save_figure
from drivers.rig_datasheet import GYRO_CHANNELS
from procedures.analysis.drift import ChannelDrift, DriftSettings


class ReportSettings(DriftSettings, Protocol):
    """The parameters the report reads (the procedure's ``DriftParams`` has them)."""

    rate_hz: float


def hours(seconds: float) -> str:
    """A duration for a caption: hours from one hour up, else seconds."""
    return f"{seconds / 3600:.3g} h" if seconds >= 3600 else f"{seconds:.4g} s"


def figure_text(r: ChannelDrift, term: str, digits: int = 3) -> str:
    """A figure for the table: the value and its 95 % interval, or "not resolved" and the interval."""
    e = r.estimate(term)
    if not (math.isfinite(e.lo) and math.isfinite(e.hi)):
        return "-"
    iv = f"[{e.lo:.{digits}g}, {e.hi:.{digits}g}]"
    return f"{e.value:.{digits + 1}g} {iv}" if e.resolved else f"not resolved, {iv}"


def read_at(r: ChannelDrift, term: str) -> str:
    t = r.arw if term == "arw" else r.bi
    if t is None or not math.isfinite(t.tau_s):
        return "-"
    return f"{t.tau_s:g} ({100 * t.share:.0f} %)"


def markdown(
    res: dict[str, ChannelDrift],
    p: ReportSettings,
    kto: dict[str, float],
    kto_source: str,
    record_s: float,
    lost: int,
    total: int,
    pickoff: dict[str, tuple[float, float]],
    kg_measured: bool,
) -> str:
    nominal_note = (
        ""
        if "NOMINAL" not in kto_source
        else "\n**K_TO: the rig's nominal data-sheet values were used** (no earth-rate result was given); "
        "K_TO only scales the rates here, so every rate below scales with it, and the 95 % intervals "
        "are widened by the data sheet's tolerance (a unit's K_TO may be that far off).\n"
    )
    lines = [
        "## Drift stability",
        "",
        f"Record: {hours(record_s)} of the torquer and pickoff outputs in Mode 3 at {p.rate_hz:g} Hz "
        f"({lost} of {total} samples lost); torquing rate r = -K_TO V_T, K_TO from the {kto_source}: "
        + ", ".join(f"{c} {kto[c]:.4g}" for c in GYRO_CHANNELS)
        + " urad/s/V.",
        nominal_note,
        "**The gyro's input rate** is reconstructed from the float's equation of motion (thesis II C.1.a(8), "
        "III A): Omega_in = sigma' + sigma / (h/k) + r, sigma the pickoff angle V_g / K_g, h/k the float's "
        "restraint time constant (data sheet, Table 3), with the viscous cross-axis coupling of "
        "II C.4.d (h/c, data sheet). The caging loop's transfer cancels out of it; what remains of the loop is the "
        "pickoff's measurement noise n, as n' + n / (h/k), which no record can take apart from the rate.",
        "",
        "| channel | ARW N (urad/sqrt s), 95 % | read at tau (s) (share) | bias instability B (urad/s), 95 % | "
        "read at tau (s) (share) | N_loop (urad/sqrt s) | mean rate (urad/s) |",
        "|---|---|---|---|---|---|---|",
    ]
    for ch, r in res.items():
        nloop = f"{r.loop.white_rate:.3g}" if r.loop else "-"
        lines.append(
            f"| {ch} | {figure_text(r, 'arw')} | {read_at(r, 'arw')} | {figure_text(r, 'bias')} | "
            f"{read_at(r, 'bias')} | {nloop} | {r.mean_rate:+.4g} |"
        )
    lines += [
        "",
        "**How N and B are read.** The overlapping Allan variance of the reconstructed rate is fitted "
        "with the IEEE 952 terms (Annex C; NIST SP 1065 Table 5): white angle noise 3 Q^2 / tau^2 (the pickoff "
        "noise, differentiated), flicker angle noise F^2 ln(tau / tau0) / tau^2 (the platform's motion), angle "
        "random walk N^2 / tau, bias instability (0.664 B)^2 and rate random walk K^2 tau / 3, at tau >= "
        f"{p.fit_tau_lo_s:g} s, non-negative, each point weighted by its degrees of freedom; F and K only where "
        "the data need them. Each of N and B is read at one averaging time chosen by the fitted model, not by "
        "the scattered curve: where the term has near its largest share of the variance (the share column) "
        f"and is best determined, with at least {p.min_edf:g} degrees of freedom. Its 95 % interval is the "
        "chi-square interval of the Allan variance there (the noise mixture's degrees of freedom, from "
        "Greenhall's per noise type: an interval for the gyro's process, not for this sample) less the other "
        "terms' modelled variance, whose own uncertainty is added in quadrature; it is capped by the "
        "model-free bound: every independent noise adds Allan variance, so a term's variance is below the "
        "upper limit of the measured one at every tau (Bonferroni over the taus), and the smallest of these "
        "bounds it.",
        "",
        "**Not resolved** means the record cannot tell the figure apart from the other terms (no share in "
        "the fitted model, nothing left after the others are taken off, or an interval wider than the "
        "value): its value is not reported, only the interval 0 .. its one-sided 95 % upper limit (for N "
        "the fit's: the read-off at the 90 % two-sided level, or the fitted coefficient plus 1.645 of its "
        "standard deviation where the fit has none of it; for B the model-free bound above). On this "
        "rig the gyro's own angle random walk is usually unresolved: the differentiated pickoff noise "
        "(Allan deviation ~ 1/tau) and the bias instability's floor cover the N / sqrt(tau) line at "
        "every tau.",
        "",
        "N_loop is not the gyro's: it is the white rate the caging loop's proportional path makes of the "
        "pickoff noise (G_p, measured as the torquing rate per pickoff angle above the loop's bandwidth, "
        "times the pickoff's noise there, over sqrt(2)), which the torquer output alone shows at short tau "
        "and which the earlier reports called ARW.",
        "",
        f"## Null stability ({p.average_s:g}-s means; thesis Table 1 style, peak-to-peak)",
        "",
        f"| channel | p-p over the record (urad/s) | record | {hours(p.null_span_s)} p-p (urad/s) | how |",
        "|---|---|---|---|---|",
    ]
    for ch, r in res.items():
        n = r.null
        if n is None:
            lines.append(f"| {ch} | - | - | - | {'; '.join(r.problems)} |")
            continue
        how = "measured" if n.measured_over_span else f"estimate: record p-p x {n.ratio:.3g}"
        lines.append(
            f"| {ch} | {n.peak_to_peak:.4g} | {hours(n.record_s)} ({n.n_averages} means) | "
            f"{n.estimate:.4g} | {how} |"
        )
    if any(r.null and not r.null.measured_over_span for r in res.values()):
        lines += [
            "",
            f"The {hours(p.null_span_s)} figure is an estimate: the record's peak-to-peak times the "
            "ratio of the rms wander of the means expected over the longer span to that over the record. "
            "The expected wander variance is half the sum of the Allan variances at the averaging time and "
            "its octaves up to the span (a Haar decomposition); beyond the longest tau with enough degrees "
            "of freedom the Allan deviation is continued with its last octave's slope clamped to 0..+1/2 "
            "(flat: flicker floor; +1/2: rate random walk). A slow trend or temperature cycle the record "
            "did not see is not in the estimate.",
        ]
    lines += [
        "",
        "## Pickoffs (the loops held them at null)",
        "",
        f"Pickoff scale K_g: {'stopwatch result' if kg_measured else 'nominal data-sheet values'}.",
        "",
        "| channel | mean (urad) | rms about mean (urad) |",
        "|---|---|---|",
    ]
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
        ax.errorbar(
            a.tau_s[ok],
            a.dev[ok],
            yerr=[a.dev[ok] - a.lo[ok], a.hi[ok] - a.dev[ok]],
            fmt="o",
            ms=3,
            color=c,
            capsize=2,
            lw=1,
            label=f"{ch} input rate",
        )
        if r.model is not None:
            t = np.geomspace(r.model.tau_fit_s[0], r.model.tau_fit_s[-1], 200)
            ax.plot(t, np.sqrt(r.model.variance(t)), "-", color=c, lw=1.5, alpha=0.7)
        if r.adev_torquer is not None:
            ax.plot(r.adev_torquer.tau_s, r.adev_torquer.dev, "-", color=c, lw=0.7, alpha=0.5)
        for t_est in (r.arw, r.bi):  # the points read, ringed
            if t_est is not None and math.isfinite(t_est.tau_s):
                i = int(np.argmin(np.abs(a.tau_s - t_est.tau_s)))
                ax.plot([a.tau_s[i]], [a.dev[i]], "o", mfc="none", mec=c, ms=10)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("averaging time tau (s)")
    ax.set_ylabel("Allan deviation (urad/s)")
    ax.set_title(
        "Drift stability, Mode 3: input rate (points, model line; ringed: read for N and B) and "
        f"torquer output alone (thin); fit from {p.fit_tau_lo_s:g} s",
        fontsize=9,
    )
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
        ax.plot(
            t,
            m - m.mean(),
            ".-",
            color=COLORS.get(ch),
            label=f"{ch}: p-p {r.null.peak_to_peak:.3g} urad/s",
        )
    ax.set_xlabel(f"time in the record ({unit_name}; gaps and resumes closed up)")
    ax.set_ylabel(f"{p.average_s:g}-s mean input rate - record mean (urad/s)")
    ax.grid(True, alpha=0.4)
    ax.legend(fontsize=8)
    save_figure(fig, path)
