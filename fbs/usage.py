"""Exit codes of every ``fbs`` command, and the argument parser that gives a usage error its own.

A script must tell a typo in its own command line from a run that aborted: argparse ends every
usage error with exit 2, the code ``fbs`` keeps for "aborted or error". ``Parser`` exits with
``EXIT_USAGE`` (64, ``EX_USAGE`` of sysexits.h) instead, and every subparser is one too
(``add_subparsers`` makes its subparsers of the parser's own class).
"""

from __future__ import annotations

import argparse
import importlib.metadata
import sys
from typing import NoReturn

EXIT_PASS = 0
EXIT_LIMITS_FAILED = 1
EXIT_ERROR = 2
EXIT_USAGE = 64

#: the exit codes as ``fbs --help`` and the README state them
EXIT_CODES_HELP = f"""\
exit codes:
  {EXIT_PASS:<3} pass: the command did what was asked (a procedure's limits all met)
  {EXIT_LIMITS_FAILED:<3} a procedure ran to the end but a measurement is outside its limits, or
      none of its headline figures was measured (each unresolved): no pass
  {EXIT_ERROR:<3} aborted or error: a bad value (e.g. --duration nan), a file or device problem,
      Ctrl-C, SIGTERM or SIGHUP (the rig is left safe), or an internal error (reported as such)
  {EXIT_USAGE:<3} usage error: unknown command or option, missing argument, an argument of the
      wrong type or not one of its choices (nothing was started)"""


class Parser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose usage errors exit ``EXIT_USAGE``, not 2."""

    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def one_line(text: str) -> str:
    """``text`` as one line of printable text: a newline or other control character (a path
    typed with one, a value pasted from elsewhere) is shown escaped (``\\n``), so an error is
    always the one line a script reads and never forges a second one."""
    return "".join(
        c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text
    )


def version() -> str:
    """The installed fbs-hil's version ("unknown" in a checkout that was never installed)."""
    try:
        return importlib.metadata.version("fbs-hil")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"
