"""``fbs run <procedure>``: a procedure for unattended use (DESIGN.md section 7).

Exit codes: 0 pass, 1 limits failed, 2 aborted or error (``fbs.usage``). ``--json`` prints
exactly the summary keys of DESIGN.md section 7 as one JSON object on stdout (logs go to
stderr). The HDF5 file, a JSON summary, a Markdown report with PNG plots and the run's log
(``<run>.log``, ``procedures.runlog``) land in ``--out``. On a terminal one status line shows the
step, the fraction done and the rig and wall time left; elsewhere plain timestamped progress
lines are logged at a modest rate (``fbs.run_progress``). ``fbs run NAME --help`` lists the
procedure's parameters (``fbs.procedure_help``), importing that procedure only then.

Earlier results: a procedure that needs another's result (stopwatch needs K_TO from
earth-rate; survey and drift use K_g and K_TO) takes the newest completed summary of that
procedure in ``--out`` (or the files given with ``--prior``); the report says which it used.
SIGTERM and SIGHUP are treated like Ctrl-C (``fbs.signals``, for every command): the rig goes
safe and the file is closed "aborted: interrupted". After a complete acquisition (during the
analysis or the report) they make the verdict "aborted" (exit 2) and the summary says what was
not written; ``--resume`` on a complete file runs its analysis again and rewrites its summary
and report (beside it, whatever ``--out``), moving nothing on the rig.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import shlex
import shutil
import socket
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from fbs import jsonout
from fbs.usage import EXIT_CODES_HELP, one_line, version
from procedures.calibrations import module_names
from procedures.runlog import RunLog

if TYPE_CHECKING:
    from procedures.procedure import Measurement

log = logging.getLogger(__name__)


def rig_url(args: argparse.Namespace) -> str:
    from drivers.rig import with_param

    url = args.rig
    if args.sim_config is not None:
        if not (url == "sim" or url.startswith("sim?")):
            raise ValueError(f"--sim-config applies to the simulated rig only, not {url!r}")
        url = with_param(url, "config", args.sim_config)
    return url


def run_command(args: argparse.Namespace) -> int:
    # the rig, the procedures and the numerics load here: the parser (`fbs --version`) needs none
    from daq.runfile import make_folder
    from drivers.rig import open_rig
    from fbs.run_progress import run_with_progress
    from procedures.calibrations import get
    from procedures.params import find_prior, parse_params
    from procedures.procedure import ProcedureError
    from procedures.resume import load_resume

    with RunLog() as runlog:
        # the log's first line (held until the log is named; never on stderr)
        log.info(
            "%s (fbs-hil %s, pid %d on %s)",
            shlex.join(["fbs", *getattr(args, "argv", [])]),
            version(),
            os.getpid(),
            socket.gethostname(),
            extra={"stderr": False},
        )
        proc_cls = get(args.procedure)
        out = Path(args.out)
        make_folder(out)  # a file in --out's way is refused before the rig opens
        resume = None
        if args.resume:
            resume = load_resume(args.resume, proc_cls, complete_ok=True)
            if args.param or args.axis:
                raise ValueError(
                    "--resume continues with the interrupted run's parameters; do not give --param/--axis"
                )
            params = proc_cls.params_from(resume.params)
        else:
            params = parse_params(proc_cls, args.param or [], args.axis)
        if resume is not None and resume.complete and not args.prior:
            prior = resume.prior  # analysed again: with the earlier results it was made with
        else:
            prior = find_prior(out, args.prior)
        proc = proc_cls(params, prior=prior)
        # Ctrl-C, SIGTERM and SIGHUP abort to the safe state (fbs.signals, set by the command line)
        try:
            with open_rig(rig_url(args)) as rig:
                summary = run_with_progress(proc, rig, out, runlog, resume=resume)
        except ProcedureError as exc:
            raise ValueError(str(exc)) from None
        # the verdict ends the log; on a terminal stdout says it (the status line's place)
        log.info(
            "fbs run %s: %s (%s); file %s; report %s",
            proc.name,
            summary.verdict,
            summary.status,
            summary.file,
            summary.report,
            extra={"progress": True},
        )
    if args.json:
        print(jsonout.dumps(summary.json_result(proc)))
    else:
        made = summary.provenance
        sim = "simulated" if made.get("simulated") else "hardware"
        print(
            f"fbs run {proc.name}: {summary.verdict} ({summary.status}) on rig "
            f"{made.get('rig')} ({sim}); file {summary.file}; report {summary.report}; "
            f"log {runlog.path}"
        )
        for m in summary.measurements:
            print(f"  {measurement_line(m)}")
        if summary.error:
            print(f"  error: {one_line(summary.error)}")
    if summary.error:
        print(f"fbs run {proc.name}: {one_line(summary.error)}", file=sys.stderr)
    return summary.exit_code


def measurement_line(m: Measurement) -> str:
    """One measurement as the text summary prints it; a NaN standard error (one repetition)
    reads "not resolved", never "± nan"; a failed one says why."""
    if m.value is None:
        return f"{m.name}: -"
    mark = {True: "pass", False: "FAIL", None: ""}[m.passed]
    if m.stderr is None:
        err = ""
    else:
        err = f" ± {m.stderr:.3g}" if math.isfinite(m.stderr) else " (not resolved)"
    why = f" ({m.note})" if m.passed is False and m.note else ""
    return f"{m.name}: {m.value:.6g}{err} {m.units} {mark}{why}"


def param_text(text: str) -> str:
    """``--param``'s ``NAME=VALUE`` form, else a usage error (64: the command line is wrong, not
    a value). The value is checked against the procedure's limits later (exit 2)."""
    name, sep, _ = text.partition("=")
    if not sep or not name.strip():
        raise argparse.ArgumentTypeError(f"{text!r}: use NAME=VALUE, e.g. repetitions=4")
    return text


def procedure_name(text: str) -> str:
    """A known procedure's name (checked against the module names, without importing them);
    else a usage error listing the known ones."""
    known = [m.replace("_", "-") for m in module_names()]
    if text not in known:
        raise argparse.ArgumentTypeError(f"unknown procedure {text!r} (known: {', '.join(known)})")
    return text


class _Help(argparse.Action):
    """``-h/--help``; after a procedure's name, its parameters too (only then is it imported)."""

    def __init__(
        self,
        option_strings: list[str],
        dest: str = argparse.SUPPRESS,
        default: str = argparse.SUPPRESS,
        help: str | None = None,
    ) -> None:
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: object,
        option_string: str | None = None,
    ) -> None:
        from fbs.procedure_help import parameter_help

        parser.print_help()
        name = getattr(namespace, "procedure", None)
        if name:
            width = max(60, min(100, shutil.get_terminal_size().columns - 2))
            print("\n" + parameter_help(name, width))
        parser.exit()


def add_parser(sub: argparse._SubParsersAction) -> None:
    known = ", ".join(m.replace("_", "-") for m in module_names())
    r = sub.add_parser(
        "run",
        help="run a procedure unattended (exit 0 pass, 1 limits failed, 2 aborted/error)",
        add_help=False,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Run a procedure on the rig, recording everything into one run file in --out\n"
        "(NAME.h5, then NAME-2.h5, ...), with its JSON summary, a Markdown report with\n"
        "plots and its log (NAME.log) beside it. On a terminal a status line shows the\n"
        "step and the time left. `fbs run PROCEDURE --help` lists its parameters.",
        epilog=EXIT_CODES_HELP,
    )
    r.add_argument(
        "-h", "--help", action=_Help, help="show this help; after PROCEDURE, its parameters too"
    )
    # Named, not imported: importing every procedure (allantools, matplotlib) would cost every
    # `fbs` command ~2 s; the name is checked against the modules' names.
    r.add_argument(
        "procedure", metavar="PROCEDURE", type=procedure_name, help=f"the procedure ({known})"
    )
    r.add_argument("--rig", default="sim", help="rig URL (default: the simulated rig, 'sim')")
    r.add_argument("--sim-config", help="TOML sim config for the simulated rig")
    r.add_argument("--axis", help="the axis or gyro channel to measure (procedure-dependent)")
    r.add_argument(
        "--out",
        default="out",
        help="directory for the run file, summary, report and log (default: out)",
    )
    r.add_argument(
        "--json",
        action="store_true",
        help="print the result as one JSON object on stdout (procedure, status, verdict, "
        "rig, simulated, sim_config, software, time; its figures per channel with "
        "K_ci95 and resolved; file): docs/schema/run-summary.schema.json",
    )
    r.add_argument(
        "--resume",
        metavar="FILE",
        help="continue an aborted run from its last completed step; "
        "a complete run: analyse it again (its summary and report rewritten)",
    )
    r.add_argument(
        "--param",
        action="append",
        metavar="NAME=VALUE",
        type=param_text,
        help="a procedure parameter (repeatable; `fbs run PROCEDURE --help` lists them)",
    )
    r.add_argument(
        "--prior",
        action="append",
        metavar="SUMMARY.json",
        help="an earlier procedure's summary to use (default: the newest in --out)",
    )
    r.set_defaults(func=run_command)
