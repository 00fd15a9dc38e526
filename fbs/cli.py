"""The ``fbs`` command line (DESIGN.md section 7). Logs go to stderr; results to stdout.

Exit codes (``fbs.usage``): 0 pass, 1 limits failed, 2 aborted or error (bad values
included), 64 usage error (argparse's own: unknown flag, missing argument, wrong type or
choice). Logging (``fbs.logsetup``): timestamped lines on stderr, this project's loggers at
INFO (DEBUG with ``-v``), other libraries' at WARNING.

Start-up: ``COMMANDS`` names each command's module. A module defines the command's options
(``add_parser``) and imports its implementation - the rig, the simulator, numpy, scipy,
numba, h5py, Textual - inside the functions that run it, so building the parser costs no
more than argparse: ``fbs --version``, ``--help`` and a usage error load none of it, and a
command loads only its own (``bench/cli_start.py`` times both; a test guards the first).

BLAS threads: OpenBLAS and MKL run one thread unless the environment sets them
(``BLAS_THREADS``, set before a command loads numpy). The analyses' matrices are small (a plant
of ~40 states, products of ~2000 x 40 x 36), where another BLAS thread costs more than it gives,
and on a busy box its spinning threads cost far more. ``fbs gap`` on a development file
(farm-bench, 3 pairs, 2 cores): idle, two threads took the same wall time as one (1.01x) and
1.7x its CPU; with two other processes running, 2.2x its wall time. A hysteresis run on the sim
rig, the rig's own threads beside its analysis, took 1.09x.
``OMP_NUM_THREADS`` is left alone: it sets how many threads a jackknife fans its replicates
over (``procedures.analysis.threads``).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import pkgutil
import select
import sys
from contextlib import nullcontext
from dataclasses import dataclass

from drivers.errors import DriverError
from fbs.logsetup import command_logging
from fbs.signals import aborting_on_signals
from fbs.usage import EXIT_CODES_HELP, EXIT_ERROR, Parser, one_line, version

log = logging.getLogger("fbs")

#: BLAS thread counts a command runs with unless its environment sets them (OpenBLAS reads its
#: own variable before ``OMP_NUM_THREADS``); children started by a command inherit them
BLAS_THREADS = {"OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


@dataclass(frozen=True)
class Command:
    """``module`` defines the command's options (``add_parser``; imported by every ``fbs``
    start, so it imports nothing heavy at its top); ``loads`` are the modules its work imports
    when it runs (a name ending in ``.*``: every module of that package). ``loads`` is what
    the bench times and a batch worker loads before it times its first file."""

    module: str
    loads: tuple[str, ...] = ()


#: every command, in ``fbs --help``'s order (``recover`` is defined by ``fbs.inspect``)
COMMANDS: dict[str, Command] = {
    "simulate": Command(
        "fbs.simulate", ("simhw.simulator", "simhw.effects", "daq.runfile", "daq.reader")
    ),
    "record": Command("fbs.record", ("drivers.rig", "daq.recorder", "daq.reader")),
    "clamp": Command("fbs.clamp", ("drivers.rig",)),
    "console": Command("fbs.console", ("console.app",)),
    "inspect": Command("fbs.inspect", ("daq.reader", "daq.recover")),
    "recover": Command("fbs.inspect", ("daq.recover",)),
    "spectra": Command("fbs.spectra", ("procedures.analysis.channel_spectra", "daq.plots")),
    "run": Command(
        "fbs.run",
        ("drivers.rig", "procedures.params", "procedures.calibrations.*", "fbs.run_progress"),
    ),
    "demo": Command(
        "fbs.demo",
        (
            "drivers.rig",
            "procedures.params",
            "procedures.calibrations.*",
            "fbs.run_progress",
            "simhw.plant",
        ),
    ),
    "analyze": Command(
        "fbs.analyze",
        (
            "procedures.analysis.hysteresis",
            "procedures.analysis.transfer",
            "procedures.reports.hysteresis",
            "procedures.reports.excitation",
        ),
    ),
    "gap": Command(
        "fbs.gap", ("procedures.analysis.gap.workflow", "procedures.analysis.gap.report")
    ),
    "batch": Command("fbs.batch"),
    "campaign": Command(
        "fbs.campaign", ("simhw.effects", "procedures.analysis.gap.grid", "daq.plots")
    ),
}


def load(*commands: str) -> None:
    """Import what ``commands`` need when they run (``COMMANDS[...].loads``), now."""
    for name in (m for c in commands for m in COMMANDS[c].loads):
        if name.endswith(".*"):
            package = importlib.import_module(name[:-2])
            for info in pkgutil.iter_modules(package.__path__):
                importlib.import_module(f"{package.__name__}.{info.name}")
        else:
            importlib.import_module(name)


def command_errors() -> tuple[type[Exception], ...]:
    """What a command reports as ``fbs CMD: error: ...`` and exit 2 (``fbs batch`` records the
    same per file): bad input, a file or a device. ``procedures.procedure.ProcedureError`` is one
    once procedures are loaded; before, none can have been raised, and this loads nothing."""
    # simhw.config.ConfigError is a ValueError
    errors: list[type[Exception]] = [ValueError, OSError, DriverError]
    procedure = sys.modules.get("procedures.procedure")
    if procedure is not None:
        errors.append(procedure.ProcedureError)
    return tuple(errors)


def build_parser() -> argparse.ArgumentParser:
    p = Parser(
        prog="fbs",
        description="Fixed Base Simulator HIL: DAQ, procedures, simulation.",
        epilog=EXIT_CODES_HELP + "\n\n`fbs COMMAND --help` describes a command; "
        "`fbs run PROCEDURE --help` lists a procedure's parameters.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "-v",
        "--verbose",
        action="store_true",
        help="debug logging of this program's own modules on stderr (other libraries stay at warnings)",
    )
    p.add_argument("--version", action="version", version=f"fbs-hil {version()}")
    # subparsers are made of the parser's own class: a usage error in any command exits 64
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    for module in dict.fromkeys(c.module for c in COMMANDS.values()):
        importlib.import_module(module).add_parser(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    """Run one ``fbs`` command; its exit code. A reader that leaves early (``fbs ... | head``)
    ends it quietly with ``EXIT_ERROR``: the output was not all written, and a traceback about
    the pipe would only hide the lines that were."""
    try:
        try:
            return _main(argv)
        finally:
            sys.stdout.flush()  # a closed pipe shows here, not at Python's exit ("ignored")
    except BrokenPipeError:
        _stdout_to_devnull()
        return EXIT_ERROR


def _stdout_to_devnull() -> None:
    """Python's recipe (the ``signal`` module's docs, "Note on SIGPIPE"): what is still buffered
    goes nowhere, so the flush at exit does not fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (AttributeError, OSError, ValueError):  # not a real file (a test's capture)
        pass


def _stdout_gone() -> bool:
    """stdout is a pipe whose reader has left (a broken pipe may be a socket's, a real error)."""
    try:
        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLERR)
        return bool(poller.poll(0))
    except (AttributeError, OSError, ValueError):  # no poll (Windows), no fd (a test's capture)
        return False


def _main(argv: list[str] | None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)  # a usage error exits 64 here
    args.argv = argv
    for var, value in BLAS_THREADS.items():  # before the command loads numpy
        os.environ.setdefault(var, value)
    with command_logging(args.verbose):
        try:
            # the console owns its terminal and its signals (Textual); every other command aborts alike
            with nullcontext() if args.command == "console" else aborting_on_signals():
                return args.func(args)
        except command_errors() as exc:
            if isinstance(exc, BrokenPipeError) and _stdout_gone():
                raise  # stdout's reader left: main ends it quietly
            print(f"fbs {args.command}: error: {one_line(str(exc))}", file=sys.stderr)
            return EXIT_ERROR
        except KeyboardInterrupt as exc:  # fbs.signals names the signal; Python's Ctrl-C: none
            why = one_line(str(exc)) or "Ctrl-C"
            print(f"fbs {args.command}: interrupted ({why})", file=sys.stderr)
            return EXIT_ERROR
        except (
            Exception
        ) as exc:  # a defect of this program: said so, never "limits failed" (exit 1)
            print(internal_error(args, exc), file=sys.stderr)
            return EXIT_ERROR


def internal_error(args: argparse.Namespace, exc: Exception) -> str:
    """The line that reports a defect, after its traceback: on stderr with ``-v``, else where
    it was kept (a run's log, ``procedures.runlog``: its path is one of the exception's notes) or how
    to see it. A user reads one line; whoever fixes it gets the traceback."""
    notes = [one_line(str(n)) for n in getattr(exc, "__notes__", ())]
    if args.verbose:
        log.error("fbs %s: internal error", args.command, exc_info=exc)
        where = "its traceback is above"
    else:
        where = "; ".join(notes) or f"`fbs -v {args.command} ...` shows its traceback"
    return (
        f"fbs {args.command}: internal error: {type(exc).__name__}: {one_line(str(exc))} "
        f"(a defect of fbs, please report it with the command line; {where})"
    )


if __name__ == "__main__":
    sys.exit(main())
