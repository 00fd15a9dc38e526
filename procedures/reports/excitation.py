"""The excitation procedure's report: the measured responses beside their fits and the
design, and a Markdown summary setting each identified figure beside the data sheet's."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from daq.plots import new_figure, save_figure
from procedures.analysis.transfer import NETWORK_CORNERS, ModelFit, Response


def plot_response(
    path: Path,
    resp: Response,
    fit: ModelFit | None,
    design: Callable[[np.ndarray], np.ndarray] | None,
) -> None:
    """Gain and phase of ``resp`` with its 95 % intervals, the fitted model and the design."""
    fig, axes = new_figure(3, 1, figsize=(9.0, 8.0))
    sel = resp.f > 0
    f = resp.f[sel]
    lo, hi = resp.gain_db_ci()
    plo, phi = resp.phase_deg_ci()
    ax_g, ax_p, ax_c = axes.flat
    ax_g.fill_between(
        f, lo[sel], hi[sel], color="C0", alpha=0.25, linewidth=0, label="95 % (jackknife)"
    )
    ax_g.semilogx(f, resp.gain_db[sel], color="C0", linewidth=0.7, label="measured")
    ax_p.fill_between(f, plo[sel], phi[sel], color="C0", alpha=0.25, linewidth=0)
    ax_p.semilogx(f, resp.phase_deg[sel], color="C0", linewidth=0.7)
    for curve, label, color in (
        (fit.curve if fit else None, "fit", "C1"),
        (design, "design", "C2"),
    ):
        if curve is None:
            continue
        h = curve(f)
        ax_g.semilogx(f, 20 * np.log10(np.abs(h)), color=color, label=label)
        ax_p.semilogx(f, np.degrees(np.angle(h)), color=color)
    if fit is not None:
        for ax in (ax_g, ax_p, ax_c):
            for edge in fit.band_hz:
                ax.axvline(edge, color="0.5", linestyle=":", linewidth=0.8)
    ax_c.semilogx(f, resp.coherence[sel], color="C3")
    ax_c.set_ylim(0, 1.05)
    via = f" via {resp.via}" if resp.via else ""
    ax_g.set_title(f"{resp.source} -> {resp.target}{via}")
    ax_g.set_ylabel("gain (dB)")
    ax_p.set_ylabel("phase (deg)")
    ax_c.set_ylabel("coherence")
    ax_c.set_xlabel("frequency (Hz)")
    for ax in axes.flat:
        ax.grid(True, which="both", alpha=0.3)
    ax_g.legend(fontsize=8)
    save_figure(fig, path)


def _fmt(v: Any) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v:.4g}"


def markdown(values: Mapping[str, Any], title: str) -> str:
    a = values["axis"]
    net = values["network"]
    design = values["network_design"]
    lines = [
        f"Excitation through V_Td, {title}. Level {values['level_V_rms']:.4g} V rms (limited by "
        f"{values['level_limited_by']}).",
        "",
        "## Compensation network (eq. 3.28), inside the excited loop through V_Td (cf. Fig. 40)",
        "",
        "| figure | measured | 95 % interval | design (Ch. III G) | resolved |",
        "|---|---|---|---|---|",
    ]
    for k in ("gain", *NETWORK_CORNERS):
        ci = net.get(f"{k}_ci95") or [None, None]
        iv = (
            "not measured"
            if _fmt(ci[0]) == _fmt(ci[1]) == "-"
            else f">= {_fmt(ci[0])}, no upper bound"
            if _fmt(ci[1]) == "-"
            else f"[{_fmt(ci[0])}, {_fmt(ci[1])}]"
        )
        lines.append(
            f"| {k} | {_fmt(net.get(k))} | {iv} | {design[k]:g} | {net['resolved'].get(k)} |"
        )
    for k, why in (net.get("why_unresolved") or {}).items():
        lines.append(f"\n* {k}: {why}")
    lines += [
        "",
        f"The fitted network differs from the design by at most {values['network_vs_design_max_db']:.3g} dB "
        f"and {values['network_vs_design_max_deg']:.3g} deg over 0.3-50 Hz.",
        "",
        "## Platform axis (eqs. 3.23-3.27), from the excited record (cf. Fig. 52)",
        "",
        f"The excited motion: {values['excitation_amplitude_urad'][a]:.3g} urad rms (the angle's part coherent "
        f"with V_Td).",
        "",
        "| figure | measured | 95 % interval | data sheet | resolved |",
        "|---|---|---|---|---|",
    ]
    amp = values["excitation_amplitude_urad"][a]
    for k, sheet in (
        ("inertia_kg_m2", values.get("datasheet_inertia_kg_m2")),
        ("damping_Nms", None),
        ("stiffness_Nm_per_rad", None),
    ):
        ci = values[f"{k}_ci95"][a]
        label = (
            f" (describing function at {amp:.3g} urad rms)"
            if values["amplitude_dependent"][k][a]
            else ""
        )
        lines.append(
            f"| {k}{label} | {_fmt(values[k][a])} | [{_fmt(ci[0])}, {_fmt(ci[1])}] | {_fmt(sheet)} | "
            f"{values['resolved'][k][a]} |"
        )
    for k, why in (values.get("platform_why_unresolved") or {}).items():
        lines.append(f"\n* {k}: {why}")
    if any(values["amplitude_dependent"][k][a] for k in ("damping_Nms", "stiffness_Nm_per_rad")):
        lines.append(
            f"\nThe axis is not linear at this amplitude (a bearing with solid friction, eq. 5.2): k and D "
            f"are its describing function (eq. 5.12) at {amp:.3g} urad rms, not constants; the small-motion "
            f"stiffness eta To^2 and the friction level To are the `hysteresis` procedure's."
        )
    lines += _roots_lines(values)
    lines += [
        "",
        "## Coherent and incoherent parts, 1-50 Hz (Ch. V C)",
        "",
        "| channel | coherent with V_Td (V rms) | incoherent (V rms) | incoherent (urad rms) | "
        "floor (urad/sqrt(Hz)) | in the loop |",
        "|---|---|---|---|---|---|",
    ]
    for c, v in values["incoherent"].items():
        lines.append(
            f"| {c} | {v['coherent_rms_V']:.4g} | {v['incoherent_rms_V']:.4g} | "
            f"{_fmt(v.get('incoherent_urad_rms'))} | {_fmt(v.get('floor_urad_per_rtHz'))} | "
            f"{'yes: the loop reshapes its noise' if v.get('in_loop') else 'no'} |"
        )
    return "\n".join(lines) + "\n"


def _sensor_source(cl: Mapping[str, Any]) -> str:
    """Where the loop's sensor gain came from, in words."""
    g = f"{cl['sensor_mV_per_urad']:.4g} mV/urad"
    if cl.get("sensor_from") == "stopwatch":
        q = cl.get("sensor_in_loop_mV_per_urad")
        return f"{g}, the stopwatch's K_g" + (
            f"; measured inside the loop through V_Td it reads {q:.4g}, the coupling in it"
            if q is not None
            else ""
        )
    return f"measured through V_Td: {g}"


def _roots_lines(values: Mapping[str, Any]) -> list[str]:
    cl = values["closed_loop"]
    th = cl["thesis"]
    roots = cl["roots"]
    ck = cl["check"]
    lines = [
        "",
        f"## Closed-loop roots, Mode {values['mode']}, from the loop's sensitivity pa / (K_d V_Td) "
        f"(cf. Table {int(th['table'])})",
        "",
        f"The axis's loop alone, closed over the parts identified above (network, platform, and "
        f"the {cl['sensor']} sensor's gain {_sensor_source(cl)}). Checked against the measured "
        f"sensitivity over {ck['band_hz'][0]:g}-{ck['band_hz'][1]:g} Hz: {ck['db_rms']:.3g} dB, "
        f"{ck['deg_rms']:.3g} deg rms ({ck['normalized']:.3g} standard errors).",
        *(
            [
                "",
                "In this gyro mode the gyro's viscous cross-axis coupling (II C.4.d) ties this loop to "
                "the other axis's; the roots are of this loop alone, as Table 6's, and the coupled "
                "rig's may lie several per cent from them where the two axes' pairs are close.",
            ]
            if cl["sensor"] == "gyro"
            else []
        ),
        "",
        "| root | measured (rad/s) | 95 % interval | zeta | 95 % interval | thesis (rad/s, zeta) |",
        "|---|---|---|---|---|---|",
    ]
    for name, (tw, tz) in (
        ("c1", (th["c1"], None)),
        ("platform_pair", (th["platform_w"], th["platform_zeta"])),
        ("c4", (th["c4"], None)),
    ):
        r = roots.get(name)
        thesis = f"{_fmt(tw)}" + ("" if tz is None else f", {_fmt(tz)}")
        if r is None:
            lines.append(f"| {name} | not found | | | | {thesis} |")
            continue
        w_ci, z_ci = r["w_rad_per_s_ci95"], r.get("zeta_ci95") or [None, None]
        lines.append(
            f"| {name} | {_fmt(r['w_rad_per_s'])} | [{_fmt(w_ci[0])}, {_fmt(w_ci[1])}] | "
            f"{_fmt(r.get('zeta'))} | [{_fmt(z_ci[0])}, {_fmt(z_ci[1])}] | {thesis} |"
        )
    lines += [f"\n* {n}" for n in cl.get("notes", [])]
    return lines
