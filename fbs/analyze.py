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
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

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
        out.mkdir(parents=True, exist_ok=True)
        stem = f"{Path(args.file).stem}-{res.axis.lower()}"
        for name, draw in (("loops", plot_loops), ("describing-function", plot_describing_function),
                           ("history", plot_history), ("path-scan", plot_scan)):
            written.append(draw(out / f"{stem}-{name}.png", res))
        md = out / f"{stem}.md"
        md.write_text(f"# fbs analyze hysteresis {Path(args.file).name} --axis {res.axis}\n\n" + markdown(res))
        written.append(md)
    return res, written


def json_result(args: argparse.Namespace) -> dict[str, Any]:
    """The object ``--json`` prints (``fbs batch analyze-hysteresis`` collects the same)."""
    return _analyse(args)[0].values()


def _hysteresis(args: argparse.Namespace) -> int:
    from procedures.reports.hysteresis import CAL_SOURCES

    if args.json:
        print(json.dumps(json_result(args)))
        return 0
    res, written = _analyse(args)
    print(f"fbs analyze hysteresis {res.file}: axis {res.axis}, {len(res.loops)} amplitudes at "
          f"{res.frequency_hz:.4g} Hz; instrument constants: {CAL_SOURCES[res.calibration_source]}")
    for key, label, unit in (("To_Nm", "To                ", "N m"), ("eta_per_Nm", "eta               ", "1/(N m)"),
                             ("stiffness_Nm_per_rad", "stiffness eta To^2", "N m/rad")):
        e = res.estimates[key]
        print(f"  {label} = {e.value:.5g} {unit}, 95 % [{e.lo:.5g}, {e.hi:.5g}]"
              + ("" if e.resolved else f" (not resolved: {e.why})"))
    print(f"  angle lag behind the power-amplifier input {res.angle_lag_s * 1e3:.3g} ms "
          f"({'± %.2g ms, measured' % (res.angle_lag_se_s * 1e3) if res.lag_source == 'measured' else res.lag_source})")
    print(f"  fit residual rms {res.residual_rms_Nm * 1e3:.3g} mN m ({100 * res.relative_residual:.3g} % of the "
          f"largest loop's torque half-range); angle path low-passed at {res.path_cutoff_hz:.3g} Hz")
    k = res.stiffness_Nm_per_rad
    for lp in res.loops:
        m = lp.describing_Nm_per_rad / k
        print(f"  {lp.amplitude_urad:8.4g} urad ({lp.n_cycles} cycles): describing function gain {abs(m):.3f} k, "
              f"phase {math.degrees(math.atan2(m.imag, m.real)):5.1f} deg; residual {lp.residual_rms_Nm * 1e3:.3g} mN m")
    for w in res.warnings:
        print(f"  warning: {w}")
    for p in written:
        print(f"  wrote {p}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    a = sub.add_parser("analyze", help="a procedure's analysis alone, on a recorded fbs-run file")
    asub = a.add_subparsers(dest="analysis", required=True, metavar="ANALYSIS")
    h = asub.add_parser("hysteresis", help="gimbal bearing friction (Dahl's To, eta; Ch. V F) from a torque-angle "
                        "sweep: needs cmd_<a>, ac_<a>_inst and pa_<a>")
    h.add_argument("file", metavar="FILE.h5", help="an fbs-run file")
    h.add_argument("--axis", default="X", help="platform axis, X or Y (default X)")
    h.add_argument("--json", action="store_true", help="print To_Nm, eta_per_Nm, stiffness_Nm_per_rad (with K_ci95 "
                   "and resolved), angle_lag_ms, file as JSON")
    h.add_argument("--out", metavar="DIR", help="write the plots and a Markdown summary to DIR")
    h.add_argument("--settle-cycles", type=int, default=1,
                   help="cycles at each new amplitude left out (default 1)")
    h.add_argument("--angle-lag-ms", type=float, default=None,
                   help="override the measured lag of the recorded angle behind the power-amplifier input (for "
                   "studies; default: measured on the record at the command's DAC lines)")
    h.set_defaults(func=_hysteresis, json_result=json_result)
