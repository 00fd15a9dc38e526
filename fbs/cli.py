"""The ``fbs`` command line (DESIGN.md section 7). Logs go to stderr; results to stdout.

Exit codes (``fbs.usage``): 0 pass, 1 limits failed, 2 aborted or error (bad values
included), 64 usage error (argparse's own: unknown flag, missing argument, wrong type or
choice). Logging (``fbs.logsetup``): timestamped lines on stderr, this project's loggers at
INFO (DEBUG with ``-v``), other libraries' at WARNING.
"""

from __future__ import annotations

import argparse
import logging
import sys
from contextlib import nullcontext

from drivers.errors import DriverError
from fbs import analyze, batch, campaign, clamp, demo, inspect, record, run, simulate, spectra
from fbs import gap as gap_cli
from fbs.logsetup import command_logging
from fbs.signals import aborting_on_signals
from fbs.usage import EXIT_CODES_HELP, EXIT_ERROR, Parser, one_line, version
from procedures.runner import ProcedureError
from simhw.params import ConfigError

log = logging.getLogger("fbs")
#: what a command reports as ``fbs CMD: error: ...`` and exit 2 (``fbs batch`` records the same per file)
COMMAND_ERRORS = (ConfigError, ValueError, OSError, DriverError, ProcedureError)


def _console(args: argparse.Namespace) -> int:
    from console.app import run_console  # Textual is imported only for the console

    return run_console(args.rig, args.out)


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="fbs", description="Fixed Base Simulator HIL: DAQ, procedures, simulation.",
               epilog=EXIT_CODES_HELP + "\n\n`fbs COMMAND --help` describes a command; "
                      "`fbs run PROCEDURE --help` lists a procedure's parameters.",
               formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-v", "--verbose", action="store_true",
                   help="debug logging of this program's own modules on stderr (other libraries stay at warnings)")
    p.add_argument("--version", action="version", version=f"fbs-hil {version()}")
    # subparsers are made of the parser's own class: a usage error in any command exits 64
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    simulate.add_parser(sub)
    record.add_parser(sub)
    clamp.add_parser(sub)
    c = sub.add_parser("console", help="the operator console (Textual): meters, modes, set-points, recording, "
                                       "procedures, spectra")
    c.add_argument("--rig", default="sim?realtime=1",
                   help="rig URL (default: the simulated rig paced to the wall clock, 'sim?realtime=1')")
    c.add_argument("--out", default="out", help="directory for recordings, procedure runs and console.log "
                                                "(default: out)")
    c.set_defaults(func=_console)

    inspect.add_parser(sub)
    spectra.add_parser(sub)
    run.add_parser(sub)
    demo.add_parser(sub)
    analyze.add_parser(sub)
    gap_cli.add_parser(sub)
    batch.add_parser(sub)
    campaign.add_parser(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)   # a usage error exits 64 here
    args.argv = argv
    with command_logging(args.verbose):
        try:
            # the console owns its terminal and its signals (Textual); every other command aborts alike
            with nullcontext() if args.command == "console" else aborting_on_signals():
                return args.func(args)
        except COMMAND_ERRORS as exc:
            print(f"fbs {args.command}: error: {one_line(str(exc))}", file=sys.stderr)
            return EXIT_ERROR
        except KeyboardInterrupt:
            print(f"fbs {args.command}: interrupted", file=sys.stderr)
            return EXIT_ERROR
        except Exception as exc:  # a defect of this program: said so, never "limits failed" (exit 1)
            log.exception("fbs %s: internal error", args.command)
            print(f"fbs {args.command}: internal error: {type(exc).__name__}: {one_line(str(exc))} (the traceback is above; "
                  "please report it with the command line)", file=sys.stderr)
            return EXIT_ERROR


if __name__ == "__main__":
    sys.exit(main())
