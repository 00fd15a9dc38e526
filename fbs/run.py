"""``fbs run <procedure>``: a procedure for unattended use (DESIGN.md section 7).

Exit codes: 0 pass, 1 limits failed, 2 aborted or error. ``--json`` prints exactly the
summary keys of DESIGN.md section 7 as one JSON object on stdout (logs go to stderr). The HDF5
file, a JSON summary and a Markdown report with PNG plots land in ``--out``.

Earlier results: a procedure that needs another's result (stopwatch needs K_TO from
earth-rate; survey and drift use K_g and K_TO) takes the newest completed summary of that
procedure in ``--out`` (or the files given with ``--prior``); the report says which it used.
SIGTERM and SIGHUP are treated like Ctrl-C (``fbs.signals``, for every command): the rig goes
safe and the file is closed "aborted: interrupted".
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from procedures.calibrations import get, module_names
from procedures.params import find_prior, parse_params
from procedures.runner import ProcedureError, load_resume, run_procedure

log = logging.getLogger(__name__)


def rig_url(args: argparse.Namespace) -> str:
    url = args.rig
    if args.sim_config:
        if not (url == "sim" or url.startswith("sim?")):
            raise ValueError(f"--sim-config applies to the simulated rig only, not {url!r}")
        url += ("&" if "?" in url else "?") + f"config={args.sim_config}"
    return url


def run_command(args: argparse.Namespace) -> int:
    from drivers.rig import open_rig

    proc_cls = get(args.procedure)
    out = Path(args.out)
    resume = None
    if args.resume:
        resume = load_resume(args.resume, proc_cls.name)
        if args.param or args.axis:
            raise ValueError("--resume continues with the interrupted run's parameters; do not give --param/--axis")
        params = proc_cls.params_from(resume.params)
    else:
        params = parse_params(proc_cls, args.param or [], args.axis)
    proc = proc_cls(params, prior=find_prior(out, args.prior))
    # Ctrl-C, SIGTERM and SIGHUP abort to the safe state (fbs.signals, set by the command line)
    try:
        with open_rig(rig_url(args)) as rig:
            summary = run_procedure(proc, rig, out, resume=resume, progress=_log_progress)
    except ProcedureError as exc:
        raise ValueError(str(exc)) from None
    if args.json:
        print(json.dumps(summary.json_values(proc_cls.json_keys)))
    else:
        print(f"fbs run {proc.name}: {summary.verdict} ({summary.status}); file {summary.file}; "
              f"report {summary.report}")
        for m in summary.measurements:
            mark = {True: "pass", False: "FAIL", None: ""}[m.passed]
            err = f" ± {m.stderr:.3g}" if m.stderr is not None else ""
            print(f"  {m.name}: {m.value:.6g}{err} {m.units} {mark}" if m.value is not None else f"  {m.name}: -")
        if summary.error:
            print(f"  error: {summary.error}")
    if summary.error:
        print(f"fbs run {proc.name}: {summary.error}", file=sys.stderr)
    return summary.exit_code


def _log_progress(p) -> None:
    left = f", about {p.remaining_wall_s:.0f} s left" if p.remaining_wall_s is not None else ""
    log.debug("%s: %3.0f %% step %d/%d %s%s", p.procedure, 100 * p.fraction, p.index + 1, p.n_steps, p.step, left)


def add_parser(sub: argparse._SubParsersAction) -> None:
    r = sub.add_parser("run", help="run a procedure unattended (exit 0 pass, 1 limits failed, 2 aborted/error)")
    # Named, not imported: importing every procedure (allantools, matplotlib) would cost every
    # `fbs` command ~2 s; an unknown name is refused by get() with the known ones listed.
    r.add_argument("procedure", metavar="PROCEDURE",
                   help="the procedure (" + ", ".join(m.replace("_", "-") for m in module_names()) + ")")
    r.add_argument("--rig", default="sim", help="rig URL (default: the simulated rig, 'sim')")
    r.add_argument("--sim-config", help="TOML sim config for the simulated rig")
    r.add_argument("--axis", help="the axis or gyro channel to measure (procedure-dependent)")
    r.add_argument("--out", default="out", help="directory for the run file, summary and report (default: out)")
    r.add_argument("--json", action="store_true", help="print the JSON summary of DESIGN.md section 7 on stdout")
    r.add_argument("--resume", metavar="FILE", help="continue an aborted run from its last completed step")
    r.add_argument("--param", action="append", metavar="NAME=VALUE", help="a procedure parameter (repeatable)")
    r.add_argument("--prior", action="append", metavar="SUMMARY.json",
                   help="an earlier procedure's summary to use (default: the newest in --out)")
    r.set_defaults(func=run_command)
