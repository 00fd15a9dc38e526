"""``fbs demo``: the whole calibration campaign on the simulated rig, and its report.

The rig starts cold (mode 1, wheels stopped), as a lab's would. The procedures run in the
order the lab runs them, each using the results before it: earth-rate (K_TO) -> stopwatch
(K_g, with the measured K_TO) -> hysteresis X and Y -> baseline X (the clamped platform's sensor
noise) -> survey (with the measured K_g, and the baseline's pickoff spectrum taken out of the
gyro's) -> excitation X in Mode 3, then in Mode 4 (the closed-loop roots of Tables 5 and 6) ->
drift (with the measured K_TO). Each leaves its HDF5 file, JSON
summary, report and log in ``--out`` and shows its progress as ``fbs run`` does; ``out/report.md`` sets every figure
measured beside the thesis's value and the simulated rig's own value. The demo, unlike the
procedures, may read the sim config: only to fill that last column. ``out/figures.json`` holds
the same rows for a program (``bench/coverage_all.py`` reads it over many drawn rigs).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fbs import jsonout
from fbs.demo_truth import OfflineRun, Truth, binomial_tail, in_interval, max_misses, param
from procedures.reports import thesis

if TYPE_CHECKING:  # the rig, the simulator and the procedures load when the demo runs
    from procedures.runner import RunSummary
    from simhw.config import SimConfig

log = logging.getLogger(__name__)

THESIS = thesis.FIGURES


def fmt(value: object) -> str:
    """``procedures.reports.procedure_report.fmt``, imported on use: the report writer is no part of
    the parser (``fbs --version`` imports this module)."""
    from procedures.reports.procedure_report import fmt as report_fmt

    return report_fmt(value)


@dataclass
class Row:
    """One figure of the report: measured, its 95 % interval, the thesis's (with where it
    stands) and the simulated rig's truth (``fbs.demo_truth.Truth``: its value, kind and how)."""

    quantity: str
    units: str
    measured: float | None
    thesis: Any
    truth: Truth | None
    note: str = ""
    interval: tuple[float, float] | None = None
    resolved: bool | None = None
    thesis_source: str = ""

    @property
    def simulated(self) -> float | None:
        return self.truth.value if self.truth is not None else None

    @property
    def covered(self) -> bool | None:
        """Whether the interval holds the simulated truth (None: no interval or no truth)."""
        return in_interval(self.simulated, self.interval)

    def as_json(self) -> dict[str, Any]:
        """The row as ``out/figures.json`` keeps it (what a coverage audit reads)."""
        t = self.truth
        return {
            "quantity": self.quantity,
            "units": self.units,
            "measured": self.measured,
            "interval": None if self.interval is None else list(self.interval),
            "resolved": self.resolved,
            "truth": None if t is None else t.value,
            "truth_kind": None if t is None else t.kind,
            "truth_exact": None if t is None else t.exact,
            "covered": self.covered,
            "note": self.note,
        }


class SimTruth:
    """The simulated rig's truth for the report's rows, from the sim config the campaign ran
    with (``fbs.demo_truth``): parameters, exact computations and, for what only a simulation
    gives (the platform's rms, a sensor's unexcited noise), offline runs of the same rig made
    on first use, ``demo_truth.OFFLINE_RECORDS`` times the record, with a seed of their own."""

    def __init__(self, cfg: SimConfig, seed: int = 0) -> None:
        self.cfg, self.seed = cfg, seed
        self._runs: dict[tuple[int, float], OfflineRun] = {}
        self.static = sim_values(cfg)

    def param(self, key: str, ch: str, how: str = "sim config") -> Truth | None:
        v = (self.static.get(key) or {}).get(ch)
        return param(v, how) if isinstance(v, (int, float)) else None

    def offline(self, mode: int, record_s: float, rate_hz: float) -> OfflineRun:
        """One offline run per mode and rate, ``OFFLINE_RECORDS`` times the first record asked for."""
        key = (mode, rate_hz)
        if key not in self._runs:
            from fbs.demo_truth import OFFLINE_RECORDS, offline_band_rms

            self._runs[key] = offline_band_rms(
                self.cfg,
                mode=mode,
                seconds=OFFLINE_RECORDS * record_s,
                rate_hz=rate_hz,
                seed=self.seed + 1_000_003 + mode,
                bands=OFFLINE_BANDS,
            )
        return self._runs[key]

    def platform_rms(
        self, axis: str, mode: int, record_s: float, rate_hz: float, band: tuple[float, float]
    ) -> Truth:
        run = self.offline(mode, record_s, rate_hz)
        v = run.theta.get((axis, *band))
        return Truth(
            v,
            "offline",
            f"the true platform angle's rms in {band[0]:g}-{band[1]:g} Hz, offline simulation "
            f"of this rig in Mode {mode}, {run.seconds:g} s",
        )

    def unexcited_gyro(
        self, axis: str, mode: int, record_s: float, rate_hz: float, band: tuple[float, float]
    ) -> Truth:
        run = self.offline(mode, record_s, rate_hz)
        v = run.gyro.get((axis, *band))
        return Truth(
            v,
            "offline",
            f"the unexcited gyro channel's rms in {band[0]:g}-{band[1]:g} Hz (pickoff noise and "
            f"the platform's own motion), offline simulation of this rig in Mode {mode}, {run.seconds:g} s",
        )


#: the bands the offline runs are read in: the survey's platform rms, the excitation's 1-50 Hz
OFFLINE_BANDS = ((0.4, 15.0), (1.0, 50.0))


def sim_values(cfg: SimConfig) -> dict[str, Any]:
    """The simulated rig's own values of what the campaign measures, as numbers (the report
    reads them through ``SimTruth``)."""
    from fbs.demo_truth import baseline_truths
    from simhw.bearing import linear_part

    dahl = {a: cfg.bearing[a].model == "dahl" for a in ("X", "Y")}
    stiff = {a: linear_part(cfg.bearing[a]).stiffness_Nm_per_rad for a in ("X", "Y")}
    base = {a: baseline_truths(cfg, a) for a in ("X", "Y")}
    return {
        "K_TO_urad_per_s_per_V": {c: g.torquer_scale_urad_per_s_per_V for c, g in cfg.gyro.items()},
        "drift_urad_per_s": {c: g.fixed_drift_urad_per_s for c, g in cfg.gyro.items()},
        **{
            f"g_drift_{a}_urad_per_s_per_g": {
                c: getattr(g, f"g_drift_{a}_urad_per_s_per_g") for c, g in cfg.gyro.items()
            }
            for a in "xyz"
        },
        "K_g_mV_per_urad": {c: g.pickoff_scale_mV_per_urad for c, g in cfg.gyro.items()},
        # Dahl's constants exist only on a Dahl bearing; its stiffness is eta To^2 for small motion
        "To_Nm": {a: cfg.bearing[a].To_Nm for a in ("X", "Y") if dahl[a]},
        "eta_per_Nm": {a: cfg.bearing[a].eta_per_Nm for a in ("X", "Y") if dahl[a]},
        "stiffness_Nm_per_rad": stiff,
        "dip_hz": {
            a: math.sqrt(stiff[a] / cfg.platform[a].inertia_kg_m2) / (2 * math.pi)
            for a in ("X", "Y")
            if stiff[a] > 0
        },
        "inertia_kg_m2": {a: cfg.platform[a].inertia_kg_m2 for a in ("X", "Y")},
        "bearing_damping_Nms": {a: linear_part(cfg.bearing[a]).damping_Nms for a in ("X", "Y")},
        "h_over_k_s": {c: g.restraint_time_s for c, g in cfg.gyro.items()},
        "bias_instability_urad_per_s": {
            c: g.bias_instability_urad_per_s for c, g in cfg.gyro.items()
        },
        "arw_urad_per_sqrt_s": {c: g.arw_urad_per_sqrt_s for c, g in cfg.gyro.items()},
        "baseline": base,
        "nea_urad": {a: {ch: t.value for ch, t in base[a]["nea_urad"].items()} for a in ("X", "Y")},
        "flicker_corner_hz": {a: cfg.autocollimator[a].flicker_corner_hz for a in ("X", "Y")},
        "pickoff_rms_urad": {
            a: {b: t.value for b, t in base[a]["pickoff_rms_urad"].items()} for a in ("X", "Y")
        },
        "pickoff_lines_hz": {a: [f for f, _ in cfg.gyro[a].pickoff_lines] for a in ("X", "Y")},
    }


def campaign() -> list[tuple[str, str | None, tuple[str, ...]]]:
    """The campaign's runs, (procedure, axis or None, its parameters), in order: every procedure
    of the catalogue says its own (``Procedure.demo_runs``, ``demo_order``), so adding one to
    the catalogue adds it here."""
    from procedures.calibrations import catalogue

    procs = sorted(catalogue().values(), key=lambda cls: (cls.demo_order, cls.name))
    return [(cls.name, axis, tuple(params)) for cls in procs for axis, params in cls.demo_runs]


def run_campaign(
    out: Path,
    *,
    cfg_path: str | None = None,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
) -> tuple[list[RunSummary], Path]:
    from daq.runfile import make_folder
    from drivers.rig import open_rig, with_param
    from fbs.run_progress import run_with_progress
    from procedures.calibrations import get
    from procedures.params import parse_params
    from procedures.runlog import RunLog
    from simhw.config import load_config
    from simhw.simulator import check_seed

    cfg = load_config(cfg_path)  # a bad config or seed is refused before anything is made
    check_seed(seed, f"--seed {seed!r}")
    make_folder(out)
    url = f"sim?seed={seed}&watchdog=5"
    if cfg_path is not None:
        url = with_param(url, "config", cfg_path)
    prior: dict[str, dict] = {}
    summaries: list[RunSummary] = []
    t0 = time.monotonic()
    with open_rig(url) as rig:
        for name, axis, params in campaign():
            cls = get(name)
            proc = cls(parse_params(cls, list(params), axis), prior=prior)
            if progress:
                progress(f"{name}{' ' + axis if axis else ''} ...")
            with RunLog() as runlog:
                s = run_with_progress(proc, rig, out, runlog)
            summaries.append(s)
            if progress:
                progress(
                    f"{name}{' ' + axis if axis else ''}: {s.verdict} ({s.status}), "
                    f"{time.monotonic() - t0:.0f} s so far"
                )
            if s.verdict in ("pass", "fail"):
                # ``_file`` as find_prior gives it: the survey reads the baseline's record there
                prior[name] = dict(s.values) | ({"_file": str(s.file)} if s.file else {})
            if s.verdict == "aborted" and s.error and "interrupted" in s.error:
                break
    report = write_campaign_report(out, summaries, SimTruth(cfg, seed), time.monotonic() - t0, seed)
    return summaries, report


def _interval(values: dict[str, Any], key: str, ch: str) -> tuple[float, float] | None:
    iv = (values.get(f"{key}_ci95") or {}).get(ch)
    if not iv or iv[0] is None or iv[1] is None:
        return None
    return float(iv[0]), float(iv[1])


def _resolved(values: dict[str, Any], key: str, ch: str) -> bool | None:
    r = ((values.get("resolved") or {}).get(key) or {}).get(ch)
    return None if r is None else bool(r)


def _figure(
    s: RunSummary,
    key: str,
    ch: str,
    label: str,
    units: str,
    thesis_key: str | None,
    truth: Truth | None,
    note: str = "",
    thesis_value: Any = None,
) -> Row:
    """A per-channel figure of a run, its interval and verdict, the thesis's value with its
    source (``thesis.SOURCES``) and the truth."""
    tk = thesis_key or key
    th = thesis_value if thesis_value is not None else (THESIS.get(tk) or {}).get(ch)
    return Row(
        label,
        units,
        (s.values.get(key) or {}).get(ch),
        th,
        truth,
        note,
        _interval(s.values, key, ch),
        _resolved(s.values, key, ch),
        thesis.source(tk, ch) if th is not None else "",
    )


def figure_rows(summaries: list[RunSummary], sim: SimTruth) -> list[Row]:
    """Every figure the campaign printed, each with its interval and the rig's truth."""
    rows: list[Row] = []
    by_name: dict[str, list[RunSummary]] = {}
    for s in summaries:
        by_name.setdefault(s.procedure, []).append(s)

    def per_channel(proc: str, key: str, label: str, units: str, note: str = "") -> None:
        for s in by_name.get(proc, []):
            for ch in s.values.get(key) or {}:
                rows.append(
                    _figure(
                        s,
                        key,
                        ch,
                        f"{label} {ch}{_in_mode(s)}",
                        units,
                        None,
                        sim.param(key, ch),
                        note,
                    )
                )

    per_channel("earth-rate", "K_TO_urad_per_s_per_V", "K_TO", "urad/s/V")
    per_channel("earth-rate", "drift_urad_per_s", "fixed drift", "urad/s")
    for a in "xyz":
        per_channel("earth-rate", f"g_drift_{a}_urad_per_s_per_g", f"g-drift along {a}", "urad/s/g")
    per_channel("stopwatch", "K_g_mV_per_urad", "K_g", "mV/urad")
    per_channel("stopwatch", "h_over_k_s", "float restraint time h/k", "s")
    for s in by_name.get("hysteresis", []):
        axis = s.params.get("axis", "X")
        for key, label, units in (
            ("To_Nm", "To", "N m"),
            ("eta_per_Nm", "eta", "1/(N m)"),
            ("stiffness_Nm_per_rad", "stiffness eta To^2", "N m/rad"),
        ):
            how = (
                "sim config"
                if key != "stiffness_Nm_per_rad"
                else "eta To^2 of the sim config (small motion)"
            )
            rows.append(
                _figure(s, key, axis, f"{label} {axis}", units, None, sim.param(key, axis, how))
            )
    for s in by_name.get("survey", []):
        _survey_rows(rows, s, sim)
    _baseline_rows(rows, by_name.get("baseline", []), sim)
    per_channel("excitation", "inertia_kg_m2", "platform inertia (V_Td -> angle)", "kg m^2")
    for s in by_name.get("excitation", []):
        _excitation_rows(rows, s, sim)
    per_channel("drift", "bias_instability_urad_per_s", "bias instability", "urad/s")
    per_channel("drift", "arw_urad_per_sqrt_s", "angle random walk", "urad/sqrt(s)")
    return rows


def _survey_rows(rows: list[Row], s: RunSummary, sim: SimTruth) -> None:
    """The survey (Ch. V E): the dip and the platform rms three ways, each beside the thesis's
    1.6 / 3.6 urad and the platform's true rms in the same band (an offline simulation)."""
    v = s.values
    mode = int(v.get("mode", 3))
    band = tuple(
        v.get("band_hz") or (s.params.get("band_lo_hz", 0.4), s.params.get("band_hi_hz", 15.0))
    )
    record_s = float(v.get("record_s") or 300.0)
    rate = float(s.params.get("rate_hz", 1000.0))
    for ch in v.get("dip_hz") or {}:
        t = sim.param(
            "dip_hz",
            ch,
            "sqrt(eta To^2 / I) / 2 pi of the sim config (the survey's motion is small: "
            "Dahl's describing function there is eta To^2 within 0.1 %)",
        )
        rows.append(_figure(s, "dip_hz", ch, f"closed-loop dip {ch}", "Hz", None, t))

    def truth(ch: str) -> Truth:
        return sim.platform_rms(ch, mode, record_s, rate, (float(band[0]), float(band[1])))

    base = v.get("baseline") or {}
    for key, label, note in (
        (
            "platform_rms_urad",
            "gyro-deduced platform rms {ch} (thesis method)",
            f"all the gyro's power in {band[0]:g}-{band[1]:g} Hz, as the thesis: pickoff noise included, so it "
            "reads above the platform's motion by design (no interval)",
        ),
        (
            "platform_rms_baseline_net_urad",
            "platform rms {ch}, net of the baseline's pickoff noise",
            f"{band[0]:g}-{band[1]:g} Hz gyro spectrum less the clamped pickoff's (Ch. V B, Fig. 33), "
            + (
                f"baseline {base.get('axis')}"
                if base.get("file")
                else f"no baseline: {base.get('from')}"
            ),
        ),
        (
            "platform_rms_net_urad",
            "platform rms {ch}, net of pickoff noise (coherent part)",
            f"the gyro's part coherent with the autocollimator, {band[0]:g}-{band[1]:g} Hz",
        ),
    ):
        for ch in v.get(key) or {}:
            rows.append(
                _figure(
                    s, key, ch, label.format(ch=ch), "urad", "platform_rms_urad", truth(ch), note
                )
            )
    cross = v.get("cross_axis_coherence") or {}
    if cross:
        rows.append(
            Row(
                "X-Y autocollimator coherence, mean 1-100 Hz",
                "",
                cross.get("mean"),
                None,
                None,
                f"independent channels: {fmt(cross.get('null_mean'))}; "
                + ("significant" if cross.get("significant") else "not significant")
                + f" (z {fmt(cross.get('z'))}; Fig. 48)",
            )
        )


def _excitation_rows(rows: list[Row], s: RunSummary, sim: SimTruth) -> None:
    """The excitation (Ch. V C-D): the bearing's stiffness at the test amplitude, the network,
    the closed-loop roots and the sensor's noise incoherent with V_Td."""
    from fbs.demo_truth import dahl_at_amplitude, dahl_equivalent_linear

    v = s.values
    axis, mode = s.params.get("axis", "X"), int(v.get("mode", s.params.get("mode", 3)))
    rms = float(s.params.get("target_urad", 2.0))
    moved = (v.get("excitation_amplitude_urad") or {}).get(axis)
    level = v.get("level_V_rms")
    dahl = sim.cfg.bearing[axis].model == "dahl"
    eq = (
        dahl_equivalent_linear(sim.cfg, axis, float(level))
        if dahl and mode == 3 and level
        else None
    )
    if "stiffness_Nm_per_rad" in v:
        if eq is not None:
            # what the run's own fit measures on this bearing at the run's own excitation level
            truth = Truth(eq.stiffness_Nm_per_rad, "offline", eq.how)
        elif not dahl:  # a linear bearing's stiffness is its own constant at any amplitude
            truth = param(sim.static["stiffness_Nm_per_rad"].get(axis), "the bearing's constant")
        else:
            truth = Truth(
                sim.static["stiffness_Nm_per_rad"].get(axis),
                "describing function",
                "the Dahl bearing's small-motion stiffness eta To^2 (not Mode 3)",
            )
        at = f" at {fmt(moved)} urad rms" if moved is not None else f" at about {fmt(rms)} urad rms"
        rows.append(
            _figure(
                s,
                "stiffness_Nm_per_rad",
                axis,
                f"bearing stiffness{at} {axis}{_in_mode(s)}",
                "N m/rad",
                None,
                truth,
                "a Dahl bearing's equivalent stiffness under this excitation (eta To^2 only for "
                "small motion): amplitude-dependent, measured at the run's own level",
            )
        )
    if "damping_Nms" in v:
        pa = sim.cfg.platform[axis]
        if not dahl:
            d = pa.gyro_damping_Nms + pa.extra_damping_Nms + sim.static["bearing_damping_Nms"][axis]
            dt = param(d, "the gyros', the extra and the bearing's viscous damping")
        elif eq is not None:  # hysteretic friction has no viscous damping: an equivalent one
            dt = Truth(eq.damping_Nms, "describing function", eq.how)
        else:
            b = sim.cfg.bearing[axis]
            w = math.sqrt(b.eta_per_Nm * b.To_Nm**2 / pa.inertia_kg_m2)
            _, d, how = dahl_at_amplitude(sim.cfg, axis, moved if moved else rms, w)
            dt = Truth(pa.gyro_damping_Nms + pa.extra_damping_Nms + d, "describing function", how)
        rows.append(
            _figure(s, "damping_Nms", axis, f"damping {axis}{_in_mode(s)}", "N m s", None, dt)
        )
    net = v.get("network") or {}
    for i in range(1, 7):
        k = f"w{i}_rad_per_s"
        if k + "_ci95" in net:
            iv = net[k + "_ci95"]
            rows.append(
                Row(
                    f"compensation corner w{i} {axis}{_in_mode(s)}",
                    "rad/s",
                    net.get(k),
                    (v.get("network_design") or {}).get(k),
                    param(getattr(sim.cfg.compensation, k)),
                    "eq. 3.28 fitted in the loop",
                    None if not iv or None in iv else (float(iv[0]), float(iv[1])),
                    net.get(k) is not None,
                    "eq. 3.28" if (v.get("network_design") or {}).get(k) is not None else "",
                )
            )
    rows.append(
        Row(
            f"compensation network vs design {axis}{_in_mode(s)}, worst 0.3-50 Hz",
            "dB",
            v.get("network_vs_design_max_db"),
            None,
            None,
            f"{fmt(v.get('network_vs_design_max_deg'))} deg (eq. 3.28, Fig. 40)",
        )
    )
    _root_rows(rows, s, sim, rms)
    if "pickoff_noise_urad_rms" in v:
        band = tuple(v.get("pickoff_noise_band_hz") or (1.0, 50.0))
        rate = float(s.params.get("rate_hz", 1000.0))
        record_s = float(s.params.get("excite_s", 256.0))
        for ch in v["pickoff_noise_urad_rms"]:
            t = sim.unexcited_gyro(ch, mode, record_s, rate, (float(band[0]), float(band[1])))
            rows.append(
                _figure(
                    s,
                    "pickoff_noise_urad_rms",
                    ch,
                    f"gyro noise {band[0]:g}-{band[1]:g} Hz, incoherent "
                    f"with V_Td {ch}{_in_mode(s)}",
                    "urad",
                    None,
                    t,
                    "the pickoff's noise with the platform's unexcited motion (Mode 3: the loop's "
                    "response to the autocollimator's noise)",
                )
            )


def _in_mode(s: RunSummary) -> str:
    """A label's mode, when it is not the thesis's usual Mode 3."""
    mode = s.values.get("mode", 3)
    return "" if mode == 3 else f" (Mode {mode})"


def _root_rows(rows: list[Row], s: RunSummary, sim: SimTruth, rms_urad: float) -> None:
    """The closed-loop roots measured (Tables 5 and 6) beside the thesis's and the simulated rig's:
    the nearest root of the axis's loop alone, linearized (``simhw.plant.linearized_poles``; a
    Dahl bearing taken at the test amplitude by its describing function, an approximation)."""
    from fbs.demo_truth import linearized_at_amplitude

    cl = s.values.get("closed_loop") or {}
    if not cl:
        return
    axis, mode, th = s.params.get("axis", "X"), int(cl.get("mode", 3)), cl.get("thesis") or {}
    if sim.cfg.bearing[axis].model == "dahl":
        lin, how = linearized_at_amplitude(sim.cfg, mode, axis, rms_urad)
        kind = "describing function"
    else:  # a linear loop: its roots are exact at any amplitude
        from simhw.plant import linearized_poles

        lin = linearized_poles(sim.cfg, mode, axis)
        how = f"the {sim.cfg.bearing[axis].model} bearing"
        kind = "computed"
    alone = " (the gyro's viscous cross-axis coupling left out)" if mode in (4, 5) else ""
    table = 5 if mode == 3 else 6
    for name, thesis_key in (("c1", "c1"), ("platform_pair", "platform_w"), ("c4", "c4")):
        r = (cl.get("roots") or {}).get(name)
        if r is None:
            continue
        p = complex(*r["pole"])
        near = min((complex(q) for q in lin), key=lambda q: abs(q - p), default=None)
        iv = r.get("w_rad_per_s_ci95") or [None, None]
        zeta = (
            f"; zeta {fmt(r.get('zeta'))} (thesis {fmt(th.get('platform_zeta'))}"
            + (f", model {fmt(-near.real / abs(near))})" if near else ")")
            if "zeta" in r
            else ""
        )
        truth = (
            Truth(abs(near), kind, f"the nearest root of the axis's loop alone{alone}, {how}")
            if near
            else None
        )
        th_value = th.get(thesis_key)
        rows.append(
            Row(
                f"closed-loop root {name} {axis} (Mode {mode})",
                "rad/s",
                r.get("w_rad_per_s"),
                th_value,
                truth,
                f"Table {table}{zeta}",
                (float(iv[0]), float(iv[1])) if iv[0] is not None else None,
                (r.get("resolved") or {}).get("w_rad_per_s"),
                thesis.source("roots", "3" if mode == 3 else "4") if th_value is not None else "",
            )
        )


def _baseline_rows(rows: list[Row], runs: list[RunSummary], sim: SimTruth) -> None:
    """The open-loop baseline's figures (Ch. V B, Table 1) beside the thesis's and the rig's."""
    ref = thesis.BASELINE
    for s in runs:
        axis = s.params.get("axis", "X")
        v = s.values
        truths = sim.static["baseline"].get(axis) or {}
        for key, label, units, thesis_of in (
            (
                "nea_urad",
                "autocollimator NEA 0.1-100 Hz",
                "urad",
                (ref["nea_urad"].get(axis) or {}).get,
            ),
            ("white_urad_per_rtHz", "autocollimator white level", "urad/sqrt(Hz)", lambda ch: None),
            ("flicker_corner_hz", "autocollimator 1/f corner", "Hz", ref["flicker_corner_hz"].get),
            (
                "pickoff_rms_urad",
                f"pickoff rms gyro {axis}",
                "urad",
                (ref["pickoff_rms_urad"].get(axis) or {}).get,
            ),
        ):
            for ch in v.get(key) or {}:
                name = f"{label} {axis} {ch}" if key != "pickoff_rms_urad" else f"{label} {ch}"
                th = thesis_of(ch)
                row = _figure(
                    s,
                    key,
                    ch,
                    name,
                    units,
                    key,
                    (truths.get(key) or {}).get(ch),
                    "clamped platform (Ch. V B)",
                    thesis_value=th,
                )
                if th is None:
                    row.thesis, row.thesis_source = None, ""
                rows.append(row)
        found = v.get("pickoff_lines_hz") or []
        truth = (sim.static.get("pickoff_lines_hz") or {}).get(axis) or []
        rows.append(
            Row(
                f"pickoff lines gyro {axis}",
                "Hz",
                None,
                None,
                None,
                f"found {', '.join(f'{f:.3f}' for f in found) or 'none'}; thesis "
                f"{', '.join(f'{f:g}' for f in ref['pickoff_lines_hz'])} (Fig. 33, pp. 119-120, Ch. V B.4: "
                f'"two large spikes separated by about 0.8 Hz" near 71 Hz); simulated '
                f"{', '.join(f'{f:g}' for f in truth)}",
            )
        )


def coverage(rows: list[Row]) -> tuple[list[Row], list[Row], list[Row], list[Row]]:
    """The rows with an interval and an exact truth, those of them whose interval excludes it,
    and the same two for the rows whose truth is approximate (describing function)."""
    exact = [r for r in rows if r.covered is not None and r.truth is not None and r.truth.exact]
    approx = [
        r for r in rows if r.covered is not None and r.truth is not None and not r.truth.exact
    ]
    return exact, [r for r in exact if not r.covered], approx, [r for r in approx if not r.covered]


def _report_header(summaries: list[RunSummary], seed: int, wall_s: float) -> list[str]:
    """Date, software version and commit, rig (``daq.provenance``), as every procedure's report."""
    from daq.provenance import header_lines, software, utc_now

    given = next((s.provenance for s in summaries if s.provenance), {})
    p = {
        "rig": given.get("rig", "sim (not stated by the runs)"),
        "simulated": given.get("simulated", True),
        "sim_config": given.get("sim_config"),
        "software": software(),
        "time": utc_now(),
    }
    return [
        *header_lines(p),
        *([] if p["sim_config"] else ["- sim config: the built-in thesis rig (no file)"]),
        f"- seed: {seed}; {len(summaries)} procedure runs in {wall_s:.0f} s wall, started cold",
    ]


def write_campaign_report(
    out: Path, summaries: list[RunSummary], sim: SimTruth, wall_s: float, seed: int
) -> Path:
    rows = figure_rows(summaries, sim)
    lines = [
        "# fbs demo: the calibration campaign on the simulated rig",
        "",
        *_report_header(summaries, seed, wall_s),
        "",
        "| procedure | verdict | status | file | report |",
        "|---|---|---|---|---|",
    ]
    for s in summaries:
        name = s.procedure + (f" {s.params['axis']}" if "axis" in s.params else "")
        lines.append(
            f"| {name} | {s.verdict} | {s.status} | `{s.file.name if s.file else '-'}` | "
            + (f"[{s.report.name}]({s.report.name})" if s.report else "-")
            + " |"
        )
    lines += [
        "",
        "## Figures measured",
        "",
        "Each figure beside the thesis's (its table or section and page below the table) and the simulated "
        "rig's truth at the conditions measured (how each truth was had is listed below the table). "
        '"in" says whether the 95 % interval holds the truth.',
        "",
        "| # | quantity | units | measured | 95 % interval | thesis | simulated truth | measured / truth - 1 "
        "| in | note |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for i, r in enumerate(rows, 1):
        err = (
            f"{100 * (r.measured / r.simulated - 1):+.2f} %"
            if r.measured is not None and r.simulated
            else "-"
        )
        iv = "-" if r.interval is None else f"[{fmt(r.interval[0])}, {fmt(r.interval[1])}]"
        if r.resolved is False:
            iv = f"not resolved: {iv}" if r.interval else "not resolved"
        inside = {True: "yes", False: "**no**", None: "-"}[r.covered]
        sim_text = fmt(r.simulated) + ("" if r.truth is None or r.truth.exact else " (approx.)")
        lines.append(
            f"| {i} | {r.quantity} | {r.units} | {fmt(r.measured)} | {iv} | {fmt(r.thesis)} | {sim_text} | "
            f"{err} | {inside} | {r.note} |"
        )
    exact, missed, approx, approx_missed = coverage(rows)
    n, k = len(exact), len(missed)
    lines += [
        "",
        "## Coverage of the intervals",
        "",
        f"{n} rows have a 95 % interval and an exact simulated truth (a parameter, an exact computation or an "
        f"offline simulation); **{k}** of them exclude it (expected about {0.05 * n:.1f}; up to "
        f"{max_misses(n)} is consistent with 95 % intervals at the 1 % level, P(>= {k}) = "
        f"{binomial_tail(k, n):.3f})"
        + (": " + "; ".join(f"#{rows.index(r) + 1} {r.quantity}" for r in missed) if missed else "")
        + ".",
        f"{len(approx)} rows have an approximate truth (a Dahl bearing's describing function at the test "
        f"amplitude, which a broadband excitation does not have exactly); {len(approx_missed)} of them exclude "
        "it"
        + (
            ": " + "; ".join(f"#{rows.index(r) + 1} {r.quantity}" for r in approx_missed)
            if approx_missed
            else ""
        )
        + ". They are not counted above.",
        "",
    ]
    lines += ["## Where the thesis states each figure", ""]
    seen: set[str] = set()
    for i, r in enumerate(rows, 1):
        if r.thesis_source and r.thesis_source not in seen:
            seen.add(r.thesis_source)
            lines.append(f"- #{i} {r.quantity}: {r.thesis_source}")
    lines += ["", "## How each simulated truth was had", ""]
    told: set[tuple[str, str]] = set()
    for i, r in enumerate(rows, 1):
        if (
            r.truth is not None
            and r.truth.how
            and (r.truth.kind, r.truth.how) not in told
            and r.truth.how != "sim config"
        ):
            told.add((r.truth.kind, r.truth.how))
            lines.append(f"- #{i} {r.quantity} ({r.truth.kind}): {r.truth.how}")
    lines += [
        "- every other row: the sim config's own parameter",
        "",
        "The simulated rig's column is read from its sim config (and offline simulations of it) for this "
        "comparison only; every procedure measured its figures through the drivers. The drift figures come "
        "from the input rate rebuilt from torquer and pickoff; the gyro's ARW is not resolved on this rig and "
        "is shown as a bound (see the drift report).",
        "",
    ]
    path = out / "report.md"
    path.write_text("\n".join(lines))
    # strict JSON for an audit's tools: an open interval end (inf) is null, as in the summaries
    (out / "figures.json").write_text(jsonout.dumps([r.as_json() for r in rows], indent=1))
    return path


def load_summaries(folder: Path) -> list[RunSummary]:
    """The campaign's runs from the JSON summaries a campaign left in ``folder`` (campaign order),
    for writing its report again (``fbs.demo`` tests use a recorded campaign's)."""

    from procedures.procedure import Verdict
    from procedures.runner import RunSummary

    order = {name: i for i, (name, _, _) in enumerate(campaign())}
    found = []
    for path in folder.glob("*.json"):
        d = json.loads(path.read_text())
        if not isinstance(d, dict) or d.get("procedure") not in order:
            continue
        stem = path.stem.rsplit("-", 1)
        n = int(stem[1]) if len(stem) == 2 and stem[1].isdigit() else 1
        s = RunSummary(
            d["procedure"],
            Path(d["file"]) if d.get("file") else None,
            d.get("status", ""),
            Verdict(d.get("verdict", "error")),
            values=d.get("values") or {},
            params=d.get("params") or {},
            error=d.get("error"),
            report=Path(d["report"]) if d.get("report") else None,
            provenance={
                k: d.get(k) for k in ("rig", "simulated", "sim_config", "software", "time")
            },
        )
        found.append((order[s.procedure], n, s))
    return [s for _, _, s in sorted(found, key=lambda t: (t[0], t[1]))]


def demo_command(args: argparse.Namespace) -> int:
    out = Path(args.out)
    summaries, report = run_campaign(
        out,
        cfg_path=args.sim_config,
        seed=args.seed,
        progress=lambda text: print(f"fbs demo: {text}", flush=True),
    )
    print(f"fbs demo: report {report}")
    print(report.read_text())
    return max(s.exit_code for s in summaries)


def add_parser(sub: argparse._SubParsersAction) -> None:
    d = sub.add_parser(
        "demo", help="the whole calibration campaign on the simulated rig, with its report"
    )
    d.add_argument("--out", default="out", help="output directory (default: out)")
    d.add_argument("--sim-config", help="TOML sim config (default: the thesis rig)")
    d.add_argument("--seed", type=int, default=0)
    d.set_defaults(func=demo_command)
