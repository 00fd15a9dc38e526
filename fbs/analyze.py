"""``fbs analyze``: a procedure's analysis alone, on any "fbs-run" file (DESIGN.md section 7).

``fbs analyze hysteresis FILE.h5 --axis X [--json] [--out DIR]``: Dahl's To and eta of the
gimbal bearing from a file with ``cmd_<a>``, ``ac_<a>_inst`` and ``pa_<a>`` channels recorded
during a sinusoidal command at a ladder of amplitudes (the ``hysteresis`` procedure's run, or
anyone's). The instrument constants are the file's ``/meta/calibration``; a file without one
is analysed with the data sheet's defaults, with a warning. ``--json`` prints exactly the keys
``To_Nm``, ``eta_per_Nm``, ``stiffness_Nm_per_rad`` (each None if the data do not resolve it),
their ``K_ci95`` and ``resolved`` ({K: {axis: bool}}), ``angle_lag_ms`` (measured on the record
and taken out) and ``file`` as one JSON object on stdout;
``--out DIR`` writes the plots and a Markdown summary there. A file that cannot be analysed
is a ValueError naming the problem (exit 2).

Both ``--json`` objects start as ``fbs run``'s do (``docs/schema/run-summary.schema.json``):
``analysis``, ``procedure`` (the analysed run's, None for a plain recording), ``status``,
``verdict`` and where the data came from (``daq.provenance``: the file's rig and whether it
was simulated; this software and the time now). The verdict follows ``fbs run``'s rule: no
headline figure resolved (hysteresis: To, eta, stiffness; transfer: any of the fit's, when a
fit is made) is "fail", exit 1. Ctrl-C (SIGTERM, SIGHUP) during the analysis prints the same
object "aborted", every figure None, and exits 2.

``fbs analyze transfer FILE.h5 --from A --to B [--via R] [--fit network|platform]
[--period S] [--start S] [--stop S] [--json] [--out DIR]``: the frequency response from channel A
to channel B (H1 = S_AB / S_AA, or S_RB / S_RA through an injected signal R inside a closed loop)
with its coherence and jackknife 95 % intervals, tabulated 0.3-100 Hz, and a fitted model: the
compensation network of eq. 3.28 (``ac_<a>_ctl`` -> ``pa_<a>``) or the platform axis's inertia,
damping and bearing stiffness (``pa_<a>`` -> ``ac_<a>_inst`` or ``_ctl``, eqs. 3.23-3.27; the
file's ``/meta/calibration`` supplies the amplifier, motor and sensor constants). ``--fit``
defaults to the model the channel pair names. ``--period`` analyses whole periods of a periodic
excitation without a window (the ``excitation`` procedure's multisine: 16 s); ``--start`` and
``--stop`` (s) pick the part of the record. ``procedures.analysis.transfer`` says how.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fbs import jsonout

if TYPE_CHECKING:
    from procedures.analysis.hysteresis import HysteresisResult


def _analyse(args: argparse.Namespace) -> tuple[HysteresisResult, list[Path]]:
    """The analysis, and the files ``--out`` wrote."""
    from procedures.analysis.hysteresis import analyze_file
    from procedures.reports.hysteresis import (
        markdown,
        plot_describing_function,
        plot_history,
        plot_loops,
        plot_scan,
    )

    if not (args.settle_cycles >= 0):
        raise ValueError(f"--settle-cycles {args.settle_cycles} must be >= 0")
    lag = None if args.angle_lag_ms is None else args.angle_lag_ms * 1e-3
    res = analyze_file(args.file, args.axis, settle_cycles=args.settle_cycles, angle_lag_s=lag)
    written: list[Path] = []
    if args.out:
        out = Path(args.out)
        from daq.runfile import make_folder

        make_folder(out)
        stem = f"{Path(args.file).stem}-{res.axis.lower()}"
        for name, draw in (
            ("loops", plot_loops),
            ("describing-function", plot_describing_function),
            ("history", plot_history),
            ("path-scan", plot_scan),
        ):
            written.append(draw(out / f"{stem}-{name}.png", res))
        md = out / f"{stem}.md"
        md.write_text(
            f"# fbs analyze hysteresis {Path(args.file).name} --axis {res.axis}\n\n" + markdown(res)
        )
        written.append(md)
    return res, written


#: exit code of each verdict (README: 0 pass, 1 no headline figure resolved, 2 aborted)
EXIT = {"pass": 0, "fail": 1, "aborted": 2}


def header(
    analysis: str, file: str | Path, verdict: str, status: str = "complete"
) -> dict[str, Any]:
    """What every analysis's ``--json`` starts with: what ran, how it ended, on whose data."""
    from daq import provenance
    from daq.reader import RunFile

    with RunFile(file) as rf:
        made = provenance.of_file(rf)
        procedure = rf.attrs.get("procedure")
    return {
        "analysis": analysis,
        "procedure": str(procedure) if procedure is not None else None,
        "status": status,
        "verdict": verdict,
        **made,
    }


def verdict_of(resolved: Any) -> str:
    """The verdict rule of ``fbs run``: "fail" when no headline figure is resolved anywhere
    (``resolved`` nested dicts of bools; None: no figure asked for, "pass")."""

    def any_true(v: Any) -> bool:
        return any(any_true(x) for x in v.values()) if isinstance(v, dict) else v is True

    return "pass" if resolved is None or any_true(resolved) else "fail"


def _aborted(args: argparse.Namespace, analysis: str, empty: dict[str, Any]) -> int:
    """Ctrl-C during an analysis with ``--json``: the object says so (exit 2)."""
    print(jsonout.dumps(header(analysis, args.file, "aborted", "aborted: interrupted") | empty))
    print(f"fbs analyze {analysis}: interrupted", file=sys.stderr)
    return EXIT["aborted"]


def json_result(args: argparse.Namespace) -> dict[str, Any]:
    """The object ``--json`` prints (``fbs batch analyze-hysteresis`` collects the same)."""
    from procedures.analysis.intervals import finite_json

    values = _analyse(args)[0].values()
    return finite_json(header("hysteresis", args.file, verdict_of(values["resolved"])) | values)


def _hysteresis_aborted(args: argparse.Namespace) -> dict[str, Any]:
    """The figures of an interrupted analysis: the shape of ``HysteresisResult.values``."""
    from procedures.analysis.hysteresis import FIGURES

    axis = str(args.axis).upper()
    out: dict[str, Any] = {k: {axis: None} for k in FIGURES}
    out |= {f"{k}_ci95": {axis: None} for k in FIGURES}
    return out | {
        "resolved": {k: {axis: False} for k in FIGURES},
        "angle_lag_ms": None,
        "file": str(args.file),
    }


def _hysteresis(args: argparse.Namespace) -> int:
    from procedures.reports.hysteresis import CAL_SOURCES

    if args.json:
        try:
            out = json_result(args)
        except KeyboardInterrupt:
            return _aborted(args, "hysteresis", _hysteresis_aborted(args))
        print(jsonout.dumps(out))
        return EXIT[out["verdict"]]
    res, written = _analyse(args)
    verdict = verdict_of(res.values()["resolved"])
    made = header("hysteresis", args.file, verdict)
    print(
        f"fbs analyze hysteresis {res.file}: {verdict}; axis {res.axis}, {len(res.loops)} "
        f"amplitudes at {res.frequency_hz:.4g} Hz; instrument constants: "
        f"{CAL_SOURCES[res.calibration_source]}; rig {made['rig']} "
        f"({_simulated_text(made['simulated'])})"
    )
    for key, label, unit in (
        ("To_Nm", "To                ", "N m"),
        ("eta_per_Nm", "eta               ", "1/(N m)"),
        ("stiffness_Nm_per_rad", "stiffness eta To^2", "N m/rad"),
    ):
        e = res.estimates[key]
        print(
            f"  {label} = {e.value:.5g} {unit}, 95 % [{e.lo:.5g}, {e.hi:.5g}]"
            + ("" if e.resolved else f" (not resolved: {e.why})")
        )
    print(
        f"  angle lag behind the power-amplifier input {res.angle_lag_s * 1e3:.3g} ms "
        f"({'± %.2g ms, measured' % (res.angle_lag_se_s * 1e3) if res.lag_source == 'measured' else res.lag_source})"
    )
    print(
        f"  fit residual rms {res.residual_rms_Nm * 1e3:.3g} mN m ({100 * res.relative_residual:.3g} % of the "
        f"largest loop's torque half-range); angle path low-passed at {res.path_cutoff_hz:.3g} Hz"
    )
    k = res.stiffness_Nm_per_rad
    for lp in res.loops:
        m = lp.describing_Nm_per_rad / k
        print(
            f"  {lp.amplitude_urad:8.4g} urad ({lp.n_cycles} cycles): describing function gain {abs(m):.3f} k, "
            f"phase {math.degrees(math.atan2(m.imag, m.real)):5.1f} deg; residual {lp.residual_rms_Nm * 1e3:.3g} mN m"
        )
    for w in res.warnings:
        print(f"  warning: {w}")
    for p in written:
        print(f"  wrote {p}")
    return EXIT[verdict]


def _simulated_text(simulated: bool | None) -> str:
    if simulated is None:
        return "simulated or not: the file does not say"
    return "simulated" if simulated else "hardware"


def _transfer_model(args: argparse.Namespace) -> str | None:
    if args.fit != "auto":
        return None if args.fit == "none" else str(args.fit)
    src, dst = args.source, args.target
    if src.startswith("ac_") and src.endswith("_ctl") and dst.startswith("pa_"):
        return "network"
    if src.startswith("pa_") and dst.startswith("ac_") and dst.endswith(("_ctl", "_inst")):
        return "platform"
    return None


#: the shortest segment (or excitation period) a spectrum is made of
MIN_SEGMENT_SAMPLES = 8


def _check_transfer_options(args: argparse.Namespace) -> None:
    """Every number of ``fbs analyze transfer`` within its limits, before the file is read."""

    def finite(name: str, v: float | None, lo: float | None = None, *, above: bool = True) -> None:
        if v is None:
            return
        if not math.isfinite(v) or (lo is not None and (v <= lo if above else v < lo)):
            rel = f"{'>' if above else '>='} {lo:g}" if lo is not None else "finite"
            raise ValueError(f"{name} {v!r} must be a finite number {rel}")

    finite("--seg-s", args.seg_s, 0.0)
    finite("--period", args.period, 0.0)
    finite("--start", args.start, 0.0, above=False)
    finite("--stop", args.stop, 0.0)
    finite("--lo-hz", args.lo_hz, 0.0, above=False)
    finite("--hi-hz", args.hi_hz, 0.0)
    if args.blocks < 2:
        raise ValueError(
            f"--blocks {args.blocks} must be at least 2 (the jackknife needs two blocks)"
        )


def transfer_result(args: argparse.Namespace) -> tuple[dict[str, Any], Any, Any]:
    """The ``--json`` object of ``fbs analyze transfer``, the response and the fit."""
    from daq.reader import RunFile
    from drivers.rig_datasheet import RigCalibration
    from procedures.analysis import transfer as tf
    from procedures.analysis.hysteresis import calibration_from_meta
    from procedures.analysis.intervals import finite_json

    names = [c for c in (args.via, args.source, args.target) if c]
    _check_transfer_options(args)
    with RunFile(args.file) as rf:
        fs, n_total, meta = rf.rate_hz, rf.n_samples, rf.meta
        missing = [c for c in names if c not in rf.channels]
        if missing:
            raise ValueError(
                f"{args.file} has no channel {', '.join(missing)} (its channels: {', '.join(rf.channels)})"
            )
    for flag, seconds in (
        ("--period", args.period),
        ("--seg-s", None if args.period is not None else args.seg_s),
    ):
        if seconds is not None and seconds * fs < MIN_SEGMENT_SAMPLES:
            raise ValueError(
                f"{flag} {seconds:g} s is {seconds * fs:.3g} samples at {fs:g} Hz: at least "
                f"{MIN_SEGMENT_SAMPLES} samples ({MIN_SEGMENT_SAMPLES / fs:g} s) are needed"
            )
    start = int(round((args.start or 0.0) * fs))
    stop = n_total if args.stop is None else min(n_total, int(round(args.stop * fs)))
    if not 0 <= start < stop:
        raise ValueError(
            f"--start {args.start} / --stop {args.stop} leave no samples of the {n_total / fs:g} s record"
        )
    if args.period is not None:
        blocks = tf.periodic_blocks([(args.file, start, stop)], names, args.period, args.blocks)
    else:
        blocks = tf.block_csd([(args.file, start, stop)], names, args.seg_s, args.blocks)
    resp = tf.response(blocks, args.source, args.target, via=args.via)
    out: dict[str, Any] = {
        "file": str(args.file),
        "from": args.source,
        "to": args.target,
        "via": args.via,
        "blocks": blocks.n_blocks,
        "seconds": round(blocks.seconds, 3),
        "measured": _measured_table(resp),
    }
    model = _transfer_model(args)
    fit = None
    out = header("transfer", args.file, "pass") | out
    lo = max(args.lo_hz, blocks.lowest_fit_hz)
    if model == "network":
        fit = tf.fit_network(resp, lo, args.hi_hz or 100.0)
    elif model == "platform":
        cal = calibration_from_meta(meta.get("calibration")) or RigCalibration()
        axis = args.target.split("_")[1].upper()
        if axis not in cal.platform or axis not in cal.autocollimator:
            raise ValueError(
                f"axis {axis}: the rig calibration has no platform and autocollimator constants for it"
            )
        fit = tf.fit_platform(
            resp, cal.platform[axis], cal.autocollimator[axis], lo, args.hi_hz or 50.0
        )
    out["model"] = model
    out["fit"] = fit.values() if fit is not None else None
    out["verdict"] = verdict_of(out["fit"]["resolved"] if out["fit"] is not None else None)
    return finite_json(out), resp, fit


def _r4(v: Any) -> float | None:
    return round(float(v), 4) if math.isfinite(float(v)) else None


def _measured_table(resp: Any) -> dict[str, list[Any]]:
    """The measured response at the bins nearest ``transfer.TABLE_HZ``."""
    from procedures.analysis.transfer import TABLE_HZ

    glo, ghi = resp.gain_db_ci()
    plo, phi = resp.phase_deg_ci()
    rows: dict[str, list[Any]] = {
        "f_hz": [],
        "gain_db": [],
        "gain_db_ci95": [],
        "phase_deg": [],
        "phase_deg_ci95": [],
        "coherence": [],
    }
    for f in TABLE_HZ:
        i = int(abs(resp.f - f).argmin())
        if abs(resp.f[i] - f) > 0.5 * f:
            continue
        rows["f_hz"].append(_r4(resp.f[i]))
        rows["gain_db"].append(_r4(resp.gain_db[i]))
        rows["gain_db_ci95"].append([_r4(glo[i]), _r4(ghi[i])])
        rows["phase_deg"].append(_r4(resp.phase_deg[i]))
        rows["phase_deg_ci95"].append([_r4(plo[i]), _r4(phi[i])])
        rows["coherence"].append(_r4(resp.coherence[i]))
    return rows


def _transfer(args: argparse.Namespace) -> int:
    from procedures.reports.excitation import plot_response

    try:
        out, resp, fit = transfer_result(args)
    except KeyboardInterrupt:
        if not args.json:
            raise
        empty = {
            "file": str(args.file),
            "from": args.source,
            "to": args.target,
            "via": args.via,
            "measured": None,
            "model": None,
            "fit": None,
        }
        return _aborted(args, "transfer", empty)
    if args.out:
        d = Path(args.out)
        from daq.runfile import make_folder

        make_folder(d)
        png = d / f"{Path(args.file).stem}-{args.source}-{args.target}.png"
        plot_response(png, resp=resp, fit=fit, design=None)
        out["plot"] = str(png)
    if args.json:
        print(jsonout.dumps(out))
        return EXIT[out["verdict"]]
    via = f" via {args.via}" if args.via else ""
    print(
        f"fbs analyze transfer {args.file}: {out['verdict']}; {args.source} -> {args.target}"
        f"{via}, {out['blocks']} blocks, {out['seconds']:g} s; rig {out['rig']} "
        f"({_simulated_text(out['simulated'])})"
    )
    m = out["measured"]
    print("    f (Hz)   gain (dB) [95 %]          phase (deg) [95 %]        coherence")
    for k, f in enumerate(m["f_hz"]):
        g, (gl, gh), ph, (pl, p2) = (
            m["gain_db"][k],
            m["gain_db_ci95"][k],
            m["phase_deg"][k],
            m["phase_deg_ci95"][k],
        )
        print(f"  {f:8.3g}   {g!s:>8} [{gl}, {gh}]   {ph!s:>8} [{pl}, {p2}]   {m['coherence'][k]}")
    if fit is not None:
        print(
            f"  {out['model']} fit over {fit.band_hz[0]:g}-{fit.band_hz[1]:g} Hz ({fit.n_bins} bins), residual "
            f"{fit.residual_db_rms:.3g} dB / {fit.residual_deg_rms:.3g} deg rms, {fit.residual_normalized:.3g} "
            f"standard errors:"
        )
        for name, e in fit.estimates.items():
            print(
                f"    {name} = {e.value:.5g}, 95 % [{e.lo:.5g}, {e.hi:.5g}]"
                + ("" if e.resolved else f" (not resolved: {e.why})")
            )
    if args.out:
        print(f"  wrote {out['plot']}")
    return EXIT[out["verdict"]]


def add_parser(sub: argparse._SubParsersAction) -> None:
    a = sub.add_parser("analyze", help="a procedure's analysis alone, on a recorded fbs-run file")
    asub = a.add_subparsers(dest="analysis", required=True, metavar="ANALYSIS")
    h = asub.add_parser(
        "hysteresis",
        help="gimbal bearing friction (Dahl's To, eta; Ch. V F) from a torque-angle "
        "sweep: needs cmd_<a>, ac_<a>_inst and pa_<a>",
    )
    h.add_argument("file", metavar="FILE.h5", help="an fbs-run file")
    h.add_argument("--axis", default="X", help="platform axis, X or Y (default X)")
    h.add_argument(
        "--json",
        action="store_true",
        help="print To_Nm, eta_per_Nm, stiffness_Nm_per_rad (with K_ci95 "
        "and resolved), angle_lag_ms, file as JSON",
    )
    h.add_argument("--out", metavar="DIR", help="write the plots and a Markdown summary to DIR")
    h.add_argument(
        "--settle-cycles",
        type=int,
        default=1,
        help="cycles at each new amplitude left out (default 1)",
    )
    h.add_argument(
        "--angle-lag-ms",
        type=float,
        default=None,
        help="override the measured lag of the recorded angle behind the power-amplifier input (for "
        "studies; default: measured on the record at the command's DAC lines)",
    )
    h.set_defaults(func=_hysteresis, json_result=json_result)

    t = asub.add_parser(
        "transfer",
        help="frequency response A -> B (H1, or through an injected R), coherence, "
        "intervals, and a fitted network (eq. 3.28) or platform (inertia, damping, stiffness)",
    )
    t.add_argument("file", metavar="FILE.h5", help="an fbs-run file")
    t.add_argument("--from", dest="source", required=True, metavar="A", help="input channel")
    t.add_argument("--to", dest="target", required=True, metavar="B", help="output channel")
    t.add_argument(
        "--via", metavar="R", help="an injected signal inside the loop (e.g. cmd_x): S_RB / S_RA"
    )
    t.add_argument(
        "--fit",
        choices=("auto", "network", "platform", "none"),
        default="auto",
        help="the model to fit (default: the one the channel pair names)",
    )
    t.add_argument(
        "--period",
        type=float,
        metavar="S",
        help="whole periods of a periodic excitation of S seconds, "
        "no window (the excitation procedure's: 16)",
    )
    t.add_argument(
        "--seg-s", type=float, default=8.0, help="Welch segment (s) without --period (default 8)"
    )
    t.add_argument("--blocks", type=int, default=8, help="jackknife blocks (default 8)")
    t.add_argument("--start", type=float, metavar="S", help="analyse from S seconds")
    t.add_argument("--stop", type=float, metavar="S", help="analyse up to S seconds")
    t.add_argument("--lo-hz", type=float, default=0.5, help="fit band low edge (default 0.5 Hz)")
    t.add_argument(
        "--hi-hz", type=float, help="fit band high edge (default 100 Hz network, 50 Hz platform)"
    )
    t.add_argument("--json", action="store_true", help="print the result as one JSON object")
    t.add_argument("--out", metavar="DIR", help="write the response plot to DIR")
    t.set_defaults(func=_transfer, json_result=lambda a: transfer_result(a)[0])
