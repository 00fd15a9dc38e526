"""``fbs gap --report DIR``: spectra plots (measured, nominal, refined), ``gap.md`` and
``refined.toml``, the refined model as a sim config (DESIGN.md section 8: a named effect is
written into the model as a TOML file ``fbs simulate --sim-config`` and ``fbs run --sim-config``
accept)."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from daq.plots import new_figure, save_figure
from daq.runfile import make_folder
from procedures.analysis.gap.workflow import GapResult
from simhw.config_dump import dump_config

log = logging.getLogger(__name__)

#: the refined model's sim config in the report directory
REFINED_NAME = "refined.toml"


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
            ax.loglog(
                fc,
                res.spectra["model_before"][i],
                color="tab:red",
                lw=0.9,
                label="nominal model (simulated)",
            )
            ax.loglog(
                fc,
                res.spectra["model_after"][i],
                color="tab:blue",
                lw=0.9,
                ls="--",
                label="refined model (simulated)",
            )
        for b in res.located:
            if b.channel == ch:
                ax.axvspan(b.f_lo_hz, b.f_hi_hz, color="tab:orange", alpha=0.15, lw=0)
        ax.set_ylabel(f"{ch}\nV$^2$/Hz")
        ax.grid(True, which="both", alpha=0.3)
    axes[-1].set_xlabel("frequency, Hz (1/24-octave bands)")
    axes[0].legend(loc="lower left", fontsize=7, ncol=2)
    found = ", ".join(f.effect for f in res.findings) or "none"
    axes[0].set_title(
        f"{Path(res.file).name}: axis {res.axis}, mode {res.mode}; effects found: {found}",
        fontsize=9,
    )
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
        ax.semilogx(
            g.band_center_hz,
            10 * np.log10(P[i] / before[i]),
            color="tab:red",
            lw=0.9,
            label="vs nominal",
        )
        ax.semilogx(
            g.band_center_hz,
            10 * np.log10(P[i] / after[i]),
            color="tab:blue",
            lw=0.9,
            label="vs refined",
        )
        ax.axhline(0, color="k", lw=0.5)
        ax.set_ylabel(f"{ch}\ndB")
        ax.grid(True, which="both", alpha=0.3)
    axes[-1].set_xlabel("frequency, Hz")
    axes[0].legend(loc="upper right", fontsize=7)
    return save_figure(fig, path)


def refined_header(res: GapResult) -> str:
    """The comment block of ``refined.toml``: what it was fitted to, the effects and their
    parameters, the noise levels, and how to use it."""
    lines = [
        f"fbs gap: the refined model of {res.file}",
        f"(axis {res.axis}, mode {res.mode}, {res.duration_s:.0f} s at {res.rate_hz:g} Hz; "
        f"channels {', '.join(res.channels)})",
        "",
    ]
    if res.findings:
        lines.append(
            "Effects named, in the order found, on axis "
            + res.axis
            + " (95 % intervals in brackets):"
        )
        lines += [f"  {i}. {f.effect}: {f.parameter_text()}" for i, f in enumerate(res.findings, 1)]
    else:
        lines.append(
            "No effect named: the nominal model with the noise levels fitted to the measurement."
        )
    if res.unexplained:
        lines.append(
            "A significant departure remains that no catalogue effect explains: this model does not close it."
        )
    lines += [
        f"Noise levels fitted (scale of the data sheet's PSD): {_fmt(res.scales_after)}.",
        "The nominal model omits the gimbal-bearing torque (DESIGN.md section 8): a bearing without a",
        'named bearing_friction is model = "none" here.',
        "Only the values that differ from the data sheet (simhw.config.SimConfig()) are written;",
        "load_config overlays them on it.",
        "",
        "Use:",
        f"  fbs simulate --sim-config {REFINED_NAME} --mode {res.mode} --duration {res.duration_s:g} "
        f"--rate {res.rate_hz:g} --out refined.h5",
        f"  fbs run PROCEDURE --sim-config {REFINED_NAME}",
    ]
    return "\n".join(lines)


def write_refined(res: GapResult, out: Path) -> tuple[Path | None, str]:
    """Write ``out/refined.toml`` from ``res.cfg_after``; returns its path (None if not
    written) and the sentence ``gap.md`` says of it. A stale file from an earlier report in the
    same directory is removed when there is nothing to write."""
    path = out / REFINED_NAME
    why = ""
    if res.cfg_after is None:
        why = "this result carries no refined model configuration"
    else:
        try:
            text = dump_config(res.cfg_after, header=refined_header(res))
        except (
            TypeError,
            ValueError,
        ) as e:  # a value TOML cannot hold: say so, keep the rest of the report
            why = f"the refined configuration cannot be written as TOML ({e})"
            log.warning("fbs gap: %s not written: %s", path, why)
        else:
            path.write_text(text)
            effects = ", ".join(f"`{f.effect}`" for f in res.findings)
            what = (
                f"the nominal model with {effects} at the fitted parameters, and the fitted noise levels"
                if effects
                else "the nominal model (no effect named) with the fitted noise levels"
            )
            return path, (
                f"`{REFINED_NAME}` is the refined model as a sim config: {what}. Simulate it with "
                f"`fbs simulate --sim-config {REFINED_NAME} --mode {res.mode} --duration {res.duration_s:g} "
                f"--rate {res.rate_hz:g} --out refined.h5`, or run a procedure on it with "
                f"`fbs run PROCEDURE --sim-config {REFINED_NAME}`."
            )
    path.unlink(missing_ok=True)
    return None, f"No `{REFINED_NAME}` was written: {why}."


def refined_config_path(res: GapResult, out: str | Path) -> Path | None:
    """Where :func:`write_report` put the refined sim config, or None if it wrote none."""
    path = Path(out) / REFINED_NAME
    return path if res.cfg_after is not None and path.exists() else None


def markdown(res: GapResult, refined_note: str = "") -> str:
    lines = [
        f"# fbs gap {Path(res.file).name}",
        "",
        f"Axis {res.axis}, mode {res.mode}, {res.duration_s:.0f} s at {res.rate_hz:g} Hz; channels "
        f"{', '.join(res.channels)}. Analysed in {res.elapsed_s:.1f} s.",
        "",
    ]
    if not res.significant:
        lines += [
            "No band departs from the nominal model beyond confidence and no offset step was found: "
            "effect **none**, `significant: false`.",
            "",
        ]
    lines += [
        f"Gap (rms of measured over model, dB, on the located bands; the models' expected spectra): "
        f"**{res.gap_before_db:.2f} dB** before, **{res.gap_after_db:.2f} dB** after.",
        "",
    ]
    if res.sim_gaps is not None:
        lines += [
            f"Against the simulated runs `model_before.h5` and `model_after.h5` (one realization each): "
            f"{res.sim_gaps[0]:.2f} dB before, {res.sim_gaps[1]:.2f} dB after.",
            "",
        ]
    if res.findings:
        lines += [
            "## Effects, in the order found",
            "",
            "| # | effect | parameters [95 % interval] | BIC score | margin over runner-up | gap closed on its bands |",
            "|---|---|---|---|---|---|",
        ]
        for i, f in enumerate(res.findings, 1):
            params = f.parameter_text("; ")
            lines.append(
                f"| {i} | `{f.effect}` | {params} | {f.score:.1f} | {f.margin:.1f} over `{f.runner_up}` | "
                f"{f.gap_before_db:.2f} -> {f.gap_after_db:.2f} dB |"
            )
        lines.append("")
    if res.unexplained:
        lines += ["A significant departure remains that no catalogue effect explains.", ""]
    lines += ["## Candidates (first look)", "", "| effect | BIC score |", "|---|---|"]
    lines += [f"| `{c['effect']}` | {c['score']:.1f} |" for c in res.candidates] + [""]
    if res.located:
        lines += [
            "## Where the measurement departs from the nominal model",
            "",
            "| channel | band, Hz | largest departure |",
            "|---|---|---|",
        ]
        lines += [
            f"| {b.channel} | {b.f_lo_hz:.3g}-{b.f_hi_hz:.3g} | {b.deviation_db:+.1f} dB at {b.peak_hz:.4g} Hz |"
            for b in res.located[:20]
        ] + [""]
    if res.steps:
        lines += [f"## Offset steps ({res.step_channel})", ""]
        lines += [
            f"- {s.time_s:.1f} s: {s.size * 1e6:+.3g} urad (z = {s.z:.1f})" for s in res.steps
        ] + [""]
    lines += [
        f"Noise levels fitted (scale of the data sheet's PSD): before {_fmt(res.scales_before)}, "
        f"after {_fmt(res.scales_after)}.",
        "",
    ]
    if refined_note:
        lines += ["## The refined model as a sim config", "", refined_note, ""]
    lines += [f"- warning: {w}" for w in res.warnings]
    lines += ["", "![spectra](spectra.png)", "", "![ratio](ratio.png)", ""]
    return "\n".join(lines)


def _fmt(d: dict[str, float]) -> str:
    return ", ".join(f"{k} {v:.3g}" for k, v in d.items()) or "-"


def write_report(res: GapResult, out: Path) -> list[Path]:
    """The plots, ``refined.toml`` (when the result has a refined model) and ``gap.md``."""
    make_folder(out)
    written = [plot_spectra(res, out / "spectra.png"), plot_ratio(res, out / "ratio.png")]
    refined, note = write_refined(res, out)
    md = out / "gap.md"
    md.write_text(markdown(res, note))
    return written + ([refined] if refined else []) + [md]
