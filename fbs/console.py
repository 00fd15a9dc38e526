"""``fbs console [--rig URL] [--out DIR]``: the operator console (``console.app``, Textual).

Only the options live here: Textual, the rig and the procedures load when the console starts.
"""

from __future__ import annotations

import argparse


def _console(args: argparse.Namespace) -> int:
    from console.app import run_console

    return run_console(args.rig, args.out)


def add_parser(sub: argparse._SubParsersAction) -> None:
    c = sub.add_parser(
        "console",
        help="the operator console (Textual): meters, modes, "
        "set-points, recording, procedures, spectra",
    )
    c.add_argument(
        "--rig",
        default="sim?realtime=1",
        help="rig URL (default: the simulated rig paced to the wall clock, 'sim?realtime=1')",
    )
    c.add_argument(
        "--out",
        default="out",
        help="directory for recordings, procedure runs and console.log (default: out)",
    )
    c.set_defaults(func=_console)
