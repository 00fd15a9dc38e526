"""The survey report: the Markdown table (each figure beside a reference column, the thesis's by
default), the notes on the gyro-deduced rms and the pickoff scale, and the dip plot. The
procedure is ``procedures.calibrations.survey``; the numbers (``SpanCsd``, ``Dip``, the PSDs)
are ``procedures.analysis.survey``; the PSD and coherence plots are ``daq.plots``'s."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from daq.plots import new_figure, save_figure
from procedures.analysis.survey import AXES, Dip, SpanCsd, SurveySettings, ac_ctl, smoothed_db


class ReportSettings(SurveySettings, Protocol):
    """The parameters the report reads (the procedure's ``SurveyParams`` has them)."""

    min_dip_depth_db: float


def markdown(
    values: Mapping[str, Any],
    dips: Mapping[str, Dip | None],
    kg_src: Mapping[str, str],
    csd: SpanCsd,
    peak_coh: Mapping[tuple[str, str], tuple[float, float]],
    p: ReportSettings,
    reference: Mapping[str, Any],
    stopwatch_from: str | None = None,
) -> str:
    """The survey's section of the report: the figures beside ``reference`` (its ``source`` names
    the column), the notes, the coherence peaks, a missing dip. ``kg_src``: where each axis's Kg
    came from ("stopwatch" or "nominal"); ``stopwatch_from``: the stopwatch summary's file."""
    ref = reference
    rref = ref.get("platform_rms_urad") or {}
    dref = ref.get("dip_hz") or {}

    def r(v: object, fmt: str = ".3g") -> str:
        return "-" if v is None else v if isinstance(v, str) else format(v, fmt)

    mode = int(values.get("mode", 3))
    sensor = "control-channel" if mode == 3 else "pickoff (in-loop sensor)"
    lines = [
        "## Survey",
        "",
        f"Mode {mode}. Record: {csd.seconds:.0f} s at {csd.fs:g} Hz; "
        f"Welch, Hann segments of {csd.nperseg / csd.fs:g} s "
        f"(bin {csd.fs / csd.nfft:.4g} Hz), 50 % overlap, {csd.segments_used} of {csd.segments_total} "
        f"segments used.",
        "",
    ]
    src = ref.get("source", "reference")
    lines += [
        f"| quantity | X | Y | {src} X | {src} Y |",
        "|---|---|---|---|---|",
        f"| dip of the {sensor} spectrum (Hz) | {r(values['dip_hz']['X'], '.3f')} | "
        f"{r(values['dip_hz']['Y'], '.3f')} | {r(dref.get('X'))} | {r(dref.get('Y'))} |",
        f"| dip depth, prominence (dB) | {r(values['dip_depth_db']['X'], '.1f')} | "
        f"{r(values['dip_depth_db']['Y'], '.1f')} | | |",
        f"| bearing stiffness the dip implies, I (2 pi f)^2 (N m/rad) | "
        f"{r(values['stiffness_from_dip_Nm_per_rad']['X'], '.4g')} | "
        f"{r(values['stiffness_from_dip_Nm_per_rad']['Y'], '.4g')} | | |",
        f"| platform rms, gyro-deduced, {p.band_lo_hz:g}-{p.band_hi_hz:g} Hz (urad) | "
        f"{r(values['platform_rms_urad']['X'], '.3f')} | {r(values['platform_rms_urad']['Y'], '.3f')} | "
        f"{r(rref.get('X'))} | {r(rref.get('Y'))} |",
        f"| autocollimator control rms, {p.band_lo_hz:g}-{p.band_hi_hz:g} Hz (urad) | "
        f"{r(values['ac_ctl_rms_urad']['X'], '.3f')} | {r(values['ac_ctl_rms_urad']['Y'], '.3f')} | | |",
        *(
            [
                f"| platform rms, out-of-loop autocollimator (instrumentation), {p.band_lo_hz:g}-{p.band_hi_hz:g} Hz "
                f"(urad) | {r(values['platform_rms_autocollimator_urad']['X'], '.3f')} | "
                f"{r(values['platform_rms_autocollimator_urad']['Y'], '.3f')} | | |"
            ]
            if "platform_rms_autocollimator_urad" in values
            else []
        ),
        f"| pickoff scale Kg used (mV/urad) | {values['pickoff_scale_mV_per_urad']['X']:.4g} "
        f"({kg_src['X']}) | {values['pickoff_scale_mV_per_urad']['Y']:.4g} ({kg_src['Y']}) | | |",
        "",
    ]
    lines += [
        "The gyro-deduced platform rms is the thesis's estimate (Ch. V E.2): the pickoff spectrum "
        f"divided by Kg^2 and integrated over {p.band_lo_hz:g}-{p.band_hi_hz:g} Hz, taken as the platform "
        "rms above 0.4 Hz because the platform does not respond above the loop bandwidth. It credits "
        "all pickoff noise in the band to platform motion, so it over-states the true motion: it "
        "measures sqrt(true^2 + pickoff noise^2) in the band (docs/procedures/survey.md).",
        "",
    ]
    lines += net_table(values, p, rref, src)
    if any(kg_src[a] == "stopwatch" for a in AXES):
        lines += [
            f"Kg from the stopwatch summary{f' `{stopwatch_from}`' if stopwatch_from else ''}.",
            "",
        ]
    nominal = [a for a in AXES if kg_src[a] == "nominal"]
    if nominal:
        lines += [
            f"**Note:** no stopwatch result was given for {', '.join(nominal)}: the pickoff scale factor "
            f"is the rig's nominal data-sheet value, so the platform rms scales with its error. Run "
            f"`stopwatch` first (or pass its summary) for a measured Kg.",
            "",
        ]
    lines += ["Coherence, largest 1-Hz average in 1-30 Hz:", ""]
    lines += [f"- {x} – {y}: {c:.2f} at {fk:.1f} Hz" for (x, y), (fk, c) in peak_coh.items()]
    lines.append("")
    for a in AXES:
        d = dips[a]
        if d is None or d.depth_db < p.min_dip_depth_db:
            lines += [
                f"**{a}: no clear dip** in {p.dip_lo_hz:g}-{p.dip_hi_hz:g} Hz (prominence "
                f"{r(d.depth_db if d else None, '.1f')} dB < {p.min_dip_depth_db:g} dB): "
                f"the spectrum only slopes, as with viscous or no bearing restraint (Ch. V F).",
                "",
            ]
    if csd.notes:
        lines += ["Spans left out: " + "; ".join(csd.notes), ""]
    return "\n".join(lines)


def net_table(
    values: Mapping[str, Any], p: SurveySettings, rref: Mapping[str, Any], src: str
) -> list[str]:
    """The platform rms three ways, side by side with the reference's (the thesis's 1.6 / 3.6 urad):
    the thesis method (all the gyro's power), net of the baseline's pickoff noise, and the gyro's
    part coherent with the instrumentation autocollimator."""

    def cell(key: str, a: str) -> str:
        v = (values.get(key) or {}).get(a)
        iv = (values.get(f"{key}_ci95") or {}).get(a) or [None, None]
        ok = ((values.get("resolved") or {}).get(key) or {}).get(a, True)
        ci = f" [{iv[0]:.3g}, {iv[1]:.3g}]" if iv[0] is not None and iv[1] is not None else ""
        if not ok:
            return f"not resolved{ci}"
        return "-" if v is None else f"{v:.3f}{ci}"

    def num(v: Any) -> str:
        return "-" if v is None else format(v, ".3g") if isinstance(v, float) else str(v)

    band = f"{p.band_lo_hz:g}-{p.band_hi_hz:g} Hz"
    base = values.get("baseline") or {}
    out = [
        f"Platform rms in {band} three ways (urad; 95 % intervals in brackets):",
        "",
        f"| axis | thesis method (Ch. V E.2) | net of the baseline's pickoff noise | coherent with the "
        f"autocollimator | {src} |",
        "|---|---|---|---|---|",
    ]
    for a in AXES:
        out.append(
            f"| {a} | {num((values.get('platform_rms_urad') or {}).get(a))} | "
            f"{cell('platform_rms_baseline_net_urad', a)} | {cell('platform_rms_net_urad', a)} | "
            f"{num(rref.get(a))} |"
        )
    out.append("")
    if base.get("file"):
        pick = values.get("baseline_pickoff_band_rms_urad") or {}
        gyro_rms = values.get("gyro_band_rms_urad") or {}
        out += [
            f"Net of the baseline: the gyro's {band} power less the same pickoff's with the platform clamped "
            f"(Ch. V B, Fig. 33), bin by bin, from the {base.get('from')} (clamped record "
            f"{base.get('record_s')} s, baseline axis {base.get('axis') or '?'}). Pickoff noise in the band, "
            "clamped: "
            + ", ".join(
                f"{a} {num(pick.get(a))} urad of the survey's {num(gyro_rms.get(a))}" for a in AXES
            )
            + ". A difference not significantly above zero is not resolved; its interval is then [0, upper].",
            "",
        ]
    else:
        out += [
            f"Net of the baseline: not measured: {base.get('from', 'no baseline run given')}.",
            "",
        ]
    return out


def plot_dips(
    path: Path,
    f: np.ndarray,
    psd_urad: Mapping[str, np.ndarray],
    dips: Mapping[str, Dip | None],
    p: SurveySettings,
) -> None:
    """The control channels' spectra over the dip search band, raw and smoothed, with the dips found."""
    fig, axes = new_figure(1, 1)
    ax = axes.flat[0]
    sel = (f >= p.dip_lo_hz) & (f <= p.dip_hi_hz)
    for k, a in enumerate(AXES):
        c = ac_ctl(a)
        ax.semilogx(
            f[sel],
            10 * np.log10(np.maximum(psd_urad[c][sel], 1e-300)),
            color=f"C{k}",
            alpha=0.3,
            linewidth=0.6,
        )
        db = smoothed_db(f, psd_urad[c], p.dip_smooth_hz)
        ax.semilogx(
            f[sel], db[sel], color=f"C{k}", label=f"{c}, smoothed over {p.dip_smooth_hz:g} Hz"
        )
        d = dips[a]
        if d is not None:
            ax.axvline(
                d.freq_hz,
                color=f"C{k}",
                linestyle="--",
                label=f"dip {a}: {d.freq_hz:.3f} Hz, {d.depth_db:.1f} dB prominence",
            )
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("PSD (dB re 1 urad²/Hz)")
    ax.set_title("Mode 3: autocollimator control-channel spectra and their dips (Ch. V E.1)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    save_figure(fig, path)
