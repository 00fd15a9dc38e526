"""``fbs demo``: the whole calibration campaign on the simulated rig, and its report.

The rig starts cold (mode 1, wheels stopped), as a lab's would. The procedures run in the
order the lab runs them, each using the results before it: earth-rate (K_TO) -> stopwatch
(K_g, with the measured K_TO) -> hysteresis X and Y -> baseline X (the clamped platform's sensor
noise) -> survey (with the measured K_g, and the baseline's pickoff spectrum taken out of the
gyro's) -> excitation X in Mode 3, then in Mode 4 (the closed-loop roots of Tables 5 and 6) ->
drift (with the measured K_TO). Each leaves its HDF5 file, JSON
summary, report and log in ``--out`` and shows its progress as ``fbs run`` does; ``out/report.md`` sets every figure
measured beside the thesis's value and the simulated rig's own value. The demo, unlike the
procedures, may read the sim config: only to fill that last column.
"""

from __future__ import annotations

import argparse
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from procedures.reports import thesis

if TYPE_CHECKING:   # the rig, the simulator and the procedures load when the demo runs
    from procedures.runner import RunSummary
    from simhw.params import SimConfig

log = logging.getLogger(__name__)

THESIS = thesis.FIGURES


def fmt(value: object) -> str:
    """``procedures.reports.report.fmt``, imported on use: the report writer is no part of
    the parser (``fbs --version`` imports this module)."""
    from procedures.reports.report import fmt as report_fmt

    return report_fmt(value)


@dataclass
class Row:
    quantity: str
    units: str
    measured: float | None
    thesis: float | None
    simulated: float | None
    note: str = ""


def sim_values(cfg: SimConfig) -> dict[str, Any]:
    """The simulated rig's own values of what the campaign measures (for the report only)."""
    from simhw.plant import linearized_poles

    stiff = {a: cfg.bearing[a].eta_per_Nm * cfg.bearing[a].To_Nm ** 2 for a in ("X", "Y")}
    return {
        "K_TO_urad_per_s_per_V": {c: g.torquer_scale_urad_per_s_per_V for c, g in cfg.gyro.items()},
        "drift_urad_per_s": {c: g.fixed_drift_urad_per_s for c, g in cfg.gyro.items()},
        **{f"g_drift_{a}_urad_per_s_per_g": {c: getattr(g, f"g_drift_{a}_urad_per_s_per_g") for c, g in cfg.gyro.items()}
           for a in "xyz"},
        "K_g_mV_per_urad": {c: g.pickoff_scale_mV_per_urad for c, g in cfg.gyro.items()},
        "To_Nm": {a: cfg.bearing[a].To_Nm for a in ("X", "Y")},
        "eta_per_Nm": {a: cfg.bearing[a].eta_per_Nm for a in ("X", "Y")},
        "stiffness_Nm_per_rad": stiff,
        "dip_hz": {a: math.sqrt(stiff[a] / cfg.platform[a].inertia_kg_m2) / (2 * math.pi) for a in ("X", "Y")},
        "inertia_kg_m2": {a: cfg.platform[a].inertia_kg_m2 for a in ("X", "Y")},
        "linearized_poles": {f"{m}{a}": [[float(q.real), float(q.imag)] for q in linearized_poles(cfg, m, a)]
                             for m in (3, 4) for a in ("X", "Y")},
        "pickoff_noise_urad_rms": {c: _pickoff_noise_1_50(g) for c, g in cfg.gyro.items()},
        "bias_instability_urad_per_s": {c: g.bias_instability_urad_per_s for c, g in cfg.gyro.items()},
        "arw_urad_per_sqrt_s": {c: g.arw_urad_per_sqrt_s for c, g in cfg.gyro.items()},
        # the control channel's NEA is the sim parameter's definition (Table 1); the azimuth's too
        "nea_urad": {a: {"ctl": cfg.autocollimator[a].nea_urad, "z": cfg.azimuth.nea_urad} for a in ("X", "Y")},
        "flicker_corner_hz": {a: cfg.autocollimator[a].flicker_corner_hz for a in ("X", "Y")},
        "pickoff_rms_urad": {a: {"1-50 Hz": _pickoff_noise_1_50(cfg.gyro[a]),
                                 "0.1-200 Hz": cfg.gyro[a].pickoff_noise_rms_urad} for a in ("X", "Y")},
        "pickoff_lines_hz": {a: [f for f, _ in cfg.gyro[a].pickoff_lines] for a in ("X", "Y")},
    }


def _pickoff_noise_1_50(g: Any) -> float:
    """The simulated pickoff noise (urad rms) in 1-50 Hz: its white level and the lines there."""
    from simhw.simulator import pickoff_white_psd

    white = pickoff_white_psd(g.pickoff_noise_rms_urad, g.pickoff_lines) * 1e12
    return math.sqrt(white * 49.0 + sum(a * a / 2 for f, a in g.pickoff_lines if 1.0 <= f <= 50.0))


#: the Mode-4 excitation's records, shorter than a lab's (the roots need no more: the tests use these)
GYRO_MODE_EXCITATION = ("mode=4", "quiet_s=64", "excite_s=160", "mode_settle_s=40")

#: (procedure, axis or None, its parameters) in campaign order
CAMPAIGN: list[tuple[str, str | None, tuple[str, ...]]] = [
    ("earth-rate", None, ()), ("stopwatch", None, ()), ("hysteresis", "X", ()), ("hysteresis", "Y", ()),
    ("baseline", "X", ()), ("survey", None, ()), ("excitation", "X", ()), ("excitation", "X", GYRO_MODE_EXCITATION),
    ("drift", None, ())]


def run_campaign(out: Path, *, cfg_path: str | None = None, seed: int = 0,
                 progress: Callable[[str], None] | None = None) -> tuple[list[RunSummary], Path]:
    from daq.runfile import make_folder
    from drivers.rig import open_rig, with_param
    from fbs.progress import run_with_progress
    from fbs.runlog import RunLog
    from procedures.calibrations import get
    from procedures.params import parse_params
    from simhw.params import load_config
    from simhw.simulator import check_seed

    cfg = load_config(cfg_path)        # a bad config or seed is refused before anything is made
    check_seed(seed, f"--seed {seed!r}")
    make_folder(out)
    url = f"sim?seed={seed}&watchdog=5"
    if cfg_path is not None:
        url = with_param(url, "config", cfg_path)
    prior: dict[str, dict] = {}
    summaries: list[RunSummary] = []
    t0 = time.monotonic()
    with open_rig(url) as rig:
        for name, axis, params in CAMPAIGN:
            cls = get(name)
            proc = cls(parse_params(cls, list(params), axis), prior=prior)
            if progress:
                progress(f"{name}{' ' + axis if axis else ''} ...")
            with RunLog() as runlog:
                s = run_with_progress(proc, rig, out, runlog)
            summaries.append(s)
            if progress:
                progress(f"{name}{' ' + axis if axis else ''}: {s.verdict} ({s.status}), "
                         f"{time.monotonic() - t0:.0f} s so far")
            if s.verdict in ("pass", "fail"):
                # ``_file`` as find_prior gives it: the survey reads the baseline's record there
                prior[name] = dict(s.values) | ({"_file": str(s.file)} if s.file else {})
            if s.verdict == "aborted" and s.error and "interrupted" in s.error:
                break
    report = write_campaign_report(out, summaries, sim_values(cfg), time.monotonic() - t0, seed)
    return summaries, report


def _rows(summaries: list[RunSummary], sim: dict[str, Any]) -> list[Row]:
    rows: list[Row] = []
    by_name: dict[str, list[RunSummary]] = {}
    for s in summaries:
        by_name.setdefault(s.procedure, []).append(s)

    def per_channel(proc: str, key: str, label: str, units: str, thesis_key: str | None = None) -> None:
        for s in by_name.get(proc, []):
            values = s.values.get(key) or {}
            ci = s.values.get(f"{key}_ci95") or {}
            resolved = (s.values.get("resolved") or {}).get(key) or {}
            for ch, v in values.items():
                iv = ci.get(ch)
                note = "" if not iv or iv[0] is None else f"95 % [{fmt(iv[0])}, {fmt(iv[1])}]"
                if resolved.get(ch) is False:
                    note = "not resolved" + (f": {note}" if note else "")
                rows.append(Row(f"{label} {ch}{_in_mode(s)}", units, v, (THESIS.get(thesis_key or key) or {}).get(ch),
                                (sim.get(key) or {}).get(ch), note))

    per_channel("earth-rate", "K_TO_urad_per_s_per_V", "K_TO", "urad/s/V")
    per_channel("earth-rate", "drift_urad_per_s", "fixed drift", "urad/s")
    for a in "xyz":
        per_channel("earth-rate", f"g_drift_{a}_urad_per_s_per_g", f"g-drift along {a}", "urad/s/g")
    per_channel("stopwatch", "K_g_mV_per_urad", "K_g", "mV/urad")
    for s in by_name.get("hysteresis", []):
        axis = s.params.get("axis", "X")
        for key, label, units in (("To_Nm", "To", "N m"), ("eta_per_Nm", "eta", "1/(N m)"),
                                  ("stiffness_Nm_per_rad", "stiffness eta To^2", "N m/rad")):
            # per axis, as every figure (issue 37)
            iv = (s.values.get(f"{key}_ci95") or {}).get(axis)
            note = "" if not iv or iv[0] is None else f"95 % [{fmt(iv[0])}, {fmt(iv[1])}]"
            if ((s.values.get("resolved") or {}).get(key) or {}).get(axis) is False:
                note = "not resolved" + (f": {note}" if note else "")
            rows.append(Row(f"{label} {axis}", units, (s.values.get(key) or {}).get(axis),
                            THESIS[key].get(axis), sim[key].get(axis), note))
    for s in by_name.get("survey", []):
        for ch, v in (s.values.get("dip_hz") or {}).items():
            rows.append(Row(f"closed-loop dip {ch}", "Hz", v, THESIS["dip_hz"].get(ch), sim["dip_hz"].get(ch),
                            "simulated: sqrt(stiffness/I)/2 pi"))
        for ch, v in (s.values.get("platform_rms_urad") or {}).items():
            rows.append(Row(f"gyro-deduced platform rms {ch}", "urad", v, THESIS["platform_rms_urad"].get(ch), None,
                            "0.4-15 Hz gyro spectrum, as the thesis (mostly pickoff noise here)"))
        base = s.values.get("baseline") or {}
        for ch in (s.values.get("platform_rms_baseline_net_urad") or {}):
            rows.append(_figure_row(s, "platform_rms_baseline_net_urad", ch, f"platform rms {ch}, net of the baseline's "
                                    "pickoff noise", "urad", THESIS["platform_rms_urad"].get(ch),
                                    "0.4-15 Hz gyro spectrum less the clamped pickoff's (Ch. V B, Fig. 33), "
                                    + (f"baseline {base.get('axis')}" if base.get("file") else
                                       f"no baseline: {base.get('from')}")))
        for ch, v in (s.values.get("platform_rms_net_urad") or {}).items():
            iv = (s.values.get("platform_rms_net_urad_ci95") or {}).get(ch) or [None, None]
            rows.append(Row(f"platform rms {ch}, net of pickoff noise (coherent part)", "urad", v,
                            THESIS["platform_rms_urad"].get(ch), None,
                            f"95 % [{fmt(iv[0])}, {fmt(iv[1])}]; the gyro's part coherent with the autocollimator, "
                            "0.4-15 Hz"))
        cross = s.values.get("cross_axis_coherence") or {}
        if cross:
            rows.append(Row("X-Y autocollimator coherence, mean 1-100 Hz", "", cross.get("mean"), None, None,
                            f"independent channels: {fmt(cross.get('null_mean'))}; "
                            + ("significant" if cross.get("significant") else "not significant")
                            + f" (z {fmt(cross.get('z'))}; Fig. 48)"))
    _baseline_rows(rows, by_name.get("baseline", []), sim)
    per_channel("excitation", "inertia_kg_m2", "platform inertia (V_Td -> angle)", "kg m^2")
    for s in by_name.get("excitation", []):
        axis = s.params.get("axis", "X")
        k = (s.values.get("stiffness_Nm_per_rad") or {}).get(axis)
        iv = (s.values.get("stiffness_Nm_per_rad_ci95") or {}).get(axis) or [None, None]
        rows.append(Row(f"bearing stiffness at {fmt(s.params.get('target_urad'))} urad rms {axis}{_in_mode(s)}",
                        "N m/rad", k,
                        THESIS["stiffness_Nm_per_rad"].get(axis), sim["stiffness_Nm_per_rad"].get(axis),
                        f"95 % [{fmt(iv[0])}, {fmt(iv[1])}]; Dahl's describing function at this amplitude, "
                        "eta To^2 only for small motion"))
        rows.append(Row(f"compensation network vs design {axis}{_in_mode(s)}, worst 0.3-50 Hz", "dB",
                        s.values.get("network_vs_design_max_db"), None, None,
                        f"{fmt(s.values.get('network_vs_design_max_deg'))} deg (eq. 3.28, Fig. 40)"))
        _root_rows(rows, s, sim)
    per_channel("excitation", "pickoff_noise_urad_rms", "pickoff noise 1-50 Hz, incoherent with V_Td", "urad")
    per_channel("drift", "bias_instability_urad_per_s", "bias instability", "urad/s")
    per_channel("drift", "arw_urad_per_sqrt_s", "angle random walk", "urad/sqrt(s)")
    return rows


def _figure_row(s: RunSummary, key: str, ch: str, label: str, units: str, thesis_value: Any, why: str) -> Row:
    """A figure with its 95 % interval, "not resolved" where the data do not resolve it."""
    iv = (s.values.get(f"{key}_ci95") or {}).get(ch) or [None, None]
    note = "" if iv[0] is None else f"95 % [{fmt(iv[0])}, {fmt(iv[1])}]; "
    if ((s.values.get("resolved") or {}).get(key) or {}).get(ch) is False:
        note = "not resolved" + (f": {note}" if note else "; ")
    return Row(label, units, (s.values.get(key) or {}).get(ch), thesis_value, None, note + why)


def _in_mode(s: RunSummary) -> str:
    """A label's mode, when it is not the thesis's usual Mode 3."""
    mode = s.values.get("mode", 3)
    return "" if mode == 3 else f" (Mode {mode})"


def _root_rows(rows: list[Row], s: RunSummary, sim: dict[str, Any]) -> None:
    """The closed-loop roots measured (Tables 5 and 6) beside the thesis's and the simulated rig's
    linearized model's nearest root."""
    cl = s.values.get("closed_loop") or {}
    if not cl:
        return
    axis, mode, th = s.params.get("axis", "X"), int(cl.get("mode", 3)), cl.get("thesis") or {}
    lin = (sim.get("linearized_poles") or {}).get(f"{mode}{axis}") or []
    for name, thesis_key in (("c1", "c1"), ("platform_pair", "platform_w"), ("c4", "c4")):
        r = (cl.get("roots") or {}).get(name)
        if r is None:
            continue
        p = complex(*r["pole"])
        near = min((complex(*q) for q in lin), key=lambda q: abs(q - p), default=None)
        iv = r.get("w_rad_per_s_ci95") or [None, None]
        zeta = (f"; zeta {fmt(r.get('zeta'))} (thesis {fmt(th.get('platform_zeta'))}"
                + (f", model {fmt(-near.real / abs(near))})" if near else ")") if "zeta" in r else "")
        rows.append(Row(f"closed-loop root {name} {axis} (Mode {mode})", "rad/s", r.get("w_rad_per_s"),
                        th.get(thesis_key), abs(near) if near is not None else None,
                        f"95 % [{fmt(iv[0])}, {fmt(iv[1])}]{zeta}; Table {int(th.get('table', 5))}; simulated: the "
                        "linearized model's (Dahl -> eta To^2)"))


def _baseline_rows(rows: list[Row], runs: list[RunSummary], sim: dict[str, Any]) -> None:
    """The open-loop baseline's figures (Ch. V B, Table 1) beside the thesis's and the rig's."""
    ref = thesis.BASELINE
    for s in runs:
        axis = s.params.get("axis", "X")
        v = s.values
        for key, label, units, thesis_of, sim_of in (
                ("nea_urad", "autocollimator NEA 0.1-100 Hz", "urad", (ref["nea_urad"].get(axis) or {}).get,
                 ((sim.get("nea_urad") or {}).get(axis) or {}).get),
                ("white_urad_per_rtHz", "autocollimator white level", "urad/sqrt(Hz)", lambda ch: None,
                 lambda ch: None),
                ("flicker_corner_hz", "autocollimator 1/f corner", "Hz", ref["flicker_corner_hz"].get,
                 dict.fromkeys(("ctl", "inst"), (sim.get("flicker_corner_hz") or {}).get(axis)).get),
                ("pickoff_rms_urad", f"pickoff rms gyro {axis}", "urad",
                 (ref["pickoff_rms_urad"].get(axis) or {}).get, ((sim.get("pickoff_rms_urad") or {}).get(axis) or {}).get)):
            ci = v.get(f"{key}_ci95") or {}
            resolved = (v.get("resolved") or {}).get(key) or {}
            for ch, x in (v.get(key) or {}).items():
                iv = ci.get(ch)
                note = "" if not iv or iv[0] is None else f"95 % [{fmt(iv[0])}, {fmt(iv[1])}]"
                if resolved.get(ch) is False:
                    note = "not resolved" + (f": {note}" if note else "")
                name = f"{label} {axis} {ch}" if key != "pickoff_rms_urad" else f"{label} {ch}"
                rows.append(Row(name, units, x, thesis_of(ch), sim_of(ch), note + "; clamped platform (Ch. V B)"))
        found = v.get("pickoff_lines_hz") or []
        truth = (sim.get("pickoff_lines_hz") or {}).get(axis) or []
        rows.append(Row(f"pickoff lines gyro {axis}", "Hz", None, None, None,
                        f"found {', '.join(f'{f:.3f}' for f in found) or 'none'}; thesis "
                        f"{', '.join(f'{f:g}' for f in ref['pickoff_lines_hz'])} (Fig. 33); simulated "
                        f"{', '.join(f'{f:g}' for f in truth)}"))


def write_campaign_report(out: Path, summaries: list[RunSummary], sim: dict[str, Any], wall_s: float,
                          seed: int) -> Path:
    lines = ["# fbs demo: the calibration campaign on the simulated rig", "",
             f"Simulated rig, seed {seed}, started cold; {len(summaries)} procedure runs in {wall_s:.0f} s wall.", "",
             "| procedure | verdict | status | file | report |", "|---|---|---|---|---|"]
    for s in summaries:
        name = s.procedure + (f" {s.params['axis']}" if "axis" in s.params else "")
        lines.append(f"| {name} | {s.verdict} | {s.status} | `{s.file.name if s.file else '-'}` | "
                     + (f"[{s.report.name}]({s.report.name})" if s.report else "-") + " |")
    lines += ["", "## Figures measured", "",
              "| quantity | units | measured | thesis | simulated rig | measured / simulated - 1 | note |",
              "|---|---|---|---|---|---|---|"]
    for r in _rows(summaries, sim):
        err = (f"{100 * (r.measured / r.simulated - 1):+.2f} %" if r.measured is not None and r.simulated
               else "-")
        lines.append(f"| {r.quantity} | {r.units} | {fmt(r.measured)} | {fmt(r.thesis)} | {fmt(r.simulated)} | "
                     f"{err} | {r.note} |")
    lines += ["", "The simulated rig's column is read from its sim config for this comparison only; every "
              "procedure measured its figures through the drivers. The drift figures come from the input rate "
              "rebuilt from torquer and pickoff; the gyro's ARW is not resolved on this rig and is shown as a "
              "bound (see the drift report).", ""]
    path = out / "report.md"
    path.write_text("\n".join(lines))
    return path


def demo_command(args: argparse.Namespace) -> int:
    out = Path(args.out)
    summaries, report = run_campaign(out, cfg_path=args.sim_config, seed=args.seed,
                                     progress=lambda text: print(f"fbs demo: {text}", flush=True))
    print(f"fbs demo: report {report}")
    print(report.read_text())
    return max(s.exit_code for s in summaries)


def add_parser(sub: argparse._SubParsersAction) -> None:
    d = sub.add_parser("demo", help="the whole calibration campaign on the simulated rig, with its report")
    d.add_argument("--out", default="out", help="output directory (default: out)")
    d.add_argument("--sim-config", help="TOML sim config (default: the thesis rig)")
    d.add_argument("--seed", type=int, default=0)
    d.set_defaults(func=demo_command)
