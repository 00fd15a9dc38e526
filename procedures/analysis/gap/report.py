"""``fbs gap --report DIR``: spectra plots (measured, nominal, refined) and ``gap.md``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from daq.plots import new_figure, save_figure
from procedures.analysis.gap.workflow import GapResult


def plot_spectra(res: GapResult, path: Path) -> Path:
    """Band spectra of every analysed channel: measured, simulated nominal and refined model,
    the measured estimate's 95 % band, and the located departures shaded."""
    import scipy.stats

    g = res.grid
    n = len(res.channels)
    fig, axes = new_figure(n, 1, figsize=(9.0, 2.6 * n + 0.6))
    axes = np.atleast_1d(axes).ravel()
    fc = g.band_center_hz
    P = res.spectra["measured"]
    lo = g.dof / scipy.stats.chi2.ppf(0.975, g.dof)
    hi = g.dof / scipy.stats.chi2.ppf(0.025, g.dof)
    for i, (ax, ch) in enumerate(zip(axes, res.channels)):
        ax.fill_between(fc, P[i] * lo, P[i] * hi, color="0.85", lw=0, label="measured, 95 %")
        ax.loglog(fc, P[i], color="k", lw=1.0, label="measured")
        if "model_before" in res.spectra:
            ax.loglog(fc, res.spectra["model_before"][i], color="tab:red", lw=0.9, label="nominal model (simulated)")
            ax.loglog(fc, res.spectra["model_after"][i], color="tab:blue", lw=0.9, ls="--",
                      label="refined model (simulated)")
        for b in res.located:
            if b.channel == ch:
                ax.axvspan(b.f_lo_hz, b.f_hi_hz, color="tab:orange", alpha=0.15, lw=0)
        ax.set_ylabel(f"{ch}\nV$^2$/Hz")
        ax.grid(True, which="both", alpha=0.3)
    axes[-1].set_xlabel("frequency, Hz (1/24-octave bands)")
    axes[0].legend(loc="lower left", fontsize=7, ncol=2)
    found = ", ".join(f.effect for f in res.findings) or "none"
    axes[0].set_title(f"{Path(res.file).name}: axis {res.axis}, mode {res.mode}; effects found: {found}", fontsize=9)
    return save_figure(fig, path)


def plot_ratio(res: GapResult, path: Path) -> Path:
    """Measured over model, dB, before and after: the gap itself."""
    g = res.grid
    fig, axes = new_figure(len(res.channels), 1, figsize=(9.0, 2.0 * len(res.channels) + 0.6))
    axes = np.atleast_1d(axes).ravel()
    P = res.spectra["measured"]
    before = res.spectra.get("model_before", res.spectra["model_before_expected"])
    after = res.spectra.get("model_after", res.spectra["model_after_expected"])
    for i, (ax, ch) in enumerate(zip(axes, res.channels)):
        ax.semilogx(g.band_center_hz, 10 * np.log10(P[i] / before[i]), color="tab:red", lw=0.9, label="vs nominal")
        ax.semilogx(g.band_center_hz, 10 * np.log10(P[i] / after[i]), color="tab:blue", lw=0.9, label="vs refined")
        ax.axhline(0, color="k", lw=0.5)
        ax.set_ylabel(f"{ch}\ndB")
        ax.grid(True, which="both", alpha=0.3)
    axes[-1].set_xlabel("frequency, Hz")
    axes[0].legend(loc="upper right", fontsize=7)
    return save_figure(fig, path)


def markdown(res: GapResult) -> str:
    lines = [f"# fbs gap {Path(res.file).name}", "",
             f"Axis {res.axis}, mode {res.mode}, {res.duration_s:.0f} s at {res.rate_hz:g} Hz; channels "
             f"{', '.join(res.channels)}. Analysed in {res.elapsed_s:.1f} s.", ""]
    if not res.significant:
        lines += ["No band departs from the nominal model beyond confidence and no offset step was found: "
                  "effect **none**, `significant: false`.", ""]
    lines += [f"Gap (rms of measured over model, dB, on the located bands; the models' expected spectra): "
              f"**{res.gap_before_db:.2f} dB** before, **{res.gap_after_db:.2f} dB** after.", ""]
    if res.sim_gaps is not None:
        lines += [f"Against the simulated runs `model_before.h5` and `model_after.h5` (one realization each): "
                  f"{res.sim_gaps[0]:.2f} dB before, {res.sim_gaps[1]:.2f} dB after.", ""]
    if res.findings:
        lines += ["## Effects, in the order found", "",
                  "| # | effect | parameters [95 % interval] | BIC score | margin over runner-up | gap closed on its bands |",
                  "|---|---|---|---|---|---|"]
        for i, f in enumerate(res.findings, 1):
            params = f.parameter_text("; ")
            lines.append(f"| {i} | `{f.effect}` | {params} | {f.score:.1f} | {f.margin:.1f} over `{f.runner_up}` | "
                         f"{f.gap_before_db:.2f} -> {f.gap_after_db:.2f} dB |")
        lines.append("")
    if res.unexplained:
        lines += ["A significant departure remains that no catalogue effect explains.", ""]
    lines += ["## Candidates (first look)", "", "| effect | BIC score |", "|---|---|"]
    lines += [f"| `{c['effect']}` | {c['score']:.1f} |" for c in res.candidates] + [""]
    if res.located:
        lines += ["## Where the measurement departs from the nominal model", "",
                  "| channel | band, Hz | largest departure |", "|---|---|---|"]
        lines += [f"| {b.channel} | {b.f_lo_hz:.3g}-{b.f_hi_hz:.3g} | {b.deviation_db:+.1f} dB at {b.peak_hz:.4g} Hz |"
                  for b in res.located[:20]] + [""]
    if res.steps:
        lines += [f"## Offset steps ({res.step_channel})", ""]
        lines += [f"- {s.time_s:.1f} s: {s.size * 1e6:+.3g} urad (z = {s.z:.1f})" for s in res.steps] + [""]
    lines += [f"Noise levels fitted (scale of the data sheet's PSD): before {_fmt(res.scales_before)}, "
              f"after {_fmt(res.scales_after)}.", ""]
    lines += [f"- warning: {w}" for w in res.warnings]
    lines += ["", "![spectra](spectra.png)", "", "![ratio](ratio.png)", ""]
    return "\n".join(lines)


def _fmt(d: dict[str, float]) -> str:
    return ", ".join(f"{k} {v:.3g}" for k, v in d.items()) or "-"


def write_report(res: GapResult, out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    written = [plot_spectra(res, out / "spectra.png"), plot_ratio(res, out / "ratio.png")]
    md = out / "gap.md"
    md.write_text(markdown(res))
    return written + [md]
