"""The ``fbs`` console script and ``python -m fbs``: the abort signals first, then the program.

A Ctrl-C, SIGTERM or SIGHUP while the command line loads printed a KeyboardInterrupt
traceback, or ended the process as the signal's (exit 130/143/129). Nothing has been done yet
then, so the handler says so and exits 2, as every other abort does (``fbs.usage``).
``fbs.cli.main`` puts the commands' own handlers (``fbs.signals``) in place once it runs; a
command's numerics (numpy, scipy, h5py, numba: a second or two) load under those.
"""

from __future__ import annotations

import os
import signal
import sys
from types import FrameType

#: ``fbs.usage.EXIT_ERROR`` (not imported: this module loads nothing before its handlers are set)
EXIT_ERROR = 2


def _starting(signum: int, frame: FrameType | None) -> None:
    sys.stderr.write(f"fbs: {signal.Signals(signum).name} while starting; nothing was done\n")
    sys.stderr.flush()
    os._exit(EXIT_ERROR)  # from anywhere in an import, without a traceback or half-run cleanup


def main() -> int:
    previous = {}
    for name in ("SIGINT", "SIGTERM", "SIGHUP"):
        sig = getattr(signal, name, None)
        if sig is not None:
            previous[sig] = signal.signal(sig, _starting)
    from fbs.cli import main as cli_main

    for sig, handler in previous.items():  # loaded: the command's own handling from here on
        signal.signal(sig, handler)
    return cli_main()
