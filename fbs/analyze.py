"""``fbs analyze``: a procedure's analysis alone, on any "fbs-run" file (DESIGN.md section 7).

``fbs analyze hysteresis FILE.h5 --axis X [--json] [--out DIR]``: Dahl's To and eta of the
gimbal bearing from a file with ``cmd_<a>``, ``ac_<a>_inst`` and ``pa_<a>`` channels recorded
during a sinusoidal command at a ladder of amplitudes (the ``hysteresis`` procedure's run, or
anyone's). The instrument constants are the file's ``/meta/calibration``; a file without one
is analysed with the data sheet's defaults, with a warning. ``--json`` prints exactly the keys
``To_Nm``, ``eta_per_Nm``, ``stiffness_Nm_per_rad``, ``file`` as one JSON object on stdout;
``--out DIR`` writes the plots and a Markdown summary there. A file that cannot be analysed
is a ValueError naming the problem (exit 2).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path


def _hysteresis(args: argparse.Namespace) -> int:
    from procedures.analysis.hysteresis import analyze_file
    from procedures.reports.hysteresis import (
        CAL_SOURCES,
        markdown,
        plot_describing_function,
        plot_history,
        plot_loops,
        plot_scan,
    )

    if not (args.settle_cycles >= 0):
        raise ValueError(f"--settle-cycles {args.settle_cycles} must be >= 0")
    res = analyze_file(args.file, args.axis, settle_cycles=args.settle_cycles, angle_lag_s=args.angle_lag_ms * 1e-3)
    written = []
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
    if args.json:
        print(json.dumps(res.values()))
        return 0
    print(f"fbs analyze hysteresis {res.file}: axis {res.axis}, {len(res.loops)} amplitudes at "
          f"{res.frequency_hz:.4g} Hz; instrument constants: {CAL_SOURCES[res.calibration_source]}")
    print(f"  To                 = {res.To_Nm:.5g} ± {res.To_se_Nm:.2g} N m")
    print(f"  eta                = {res.eta_per_Nm:.5g} ± {res.eta_se_per_Nm:.2g} 1/(N m)")
    print(f"  stiffness eta To^2 = {res.stiffness_Nm_per_rad:.5g} ± {res.stiffness_se_Nm_per_rad:.2g} N m/rad")
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
    h.add_argument("--json", action="store_true", help="print To_Nm, eta_per_Nm, stiffness_Nm_per_rad, file as JSON")
    h.add_argument("--out", metavar="DIR", help="write the plots and a Markdown summary to DIR")
    h.add_argument("--settle-cycles", type=int, default=1,
                   help="cycles at each new amplitude left out (default 1)")
    h.add_argument("--angle-lag-ms", type=float, default=0.0,
                   help="advance the recorded angle by this much: the instrumentation channel's lag behind the "
                   "power-amplifier input, if the data sheet gives it (default 0)")
    h.set_defaults(func=_hysteresis)
