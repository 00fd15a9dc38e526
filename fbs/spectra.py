"""``fbs spectra FILE.h5 --channels a,b [--out DIR] [--seg-s S]`` (DESIGN.md section 7).

The numerics and the files written are ``procedures.analysis.spectra``'s; this is the command line.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from procedures.analysis.spectra import default_out_dir, spectra_command


def _run(args: argparse.Namespace) -> int:
    channels = [c for c in args.channels.split(",") if c.strip()]
    out = Path(args.out) if args.out else default_out_dir(args.file)
    result = spectra_command(args.file, channels, out, seg_s=args.seg_s)
    for p in result.files:
        print(f"wrote {p}")
    for line in result.lines():
        print(line)
    return 0


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``spectra`` on the ``fbs`` subcommands (``sub`` from ``add_subparsers``)."""
    s = sub.add_parser("spectra", help="PSD and coherence plots of a run file (App. A.8 octave bands)",
                       description="PSD of each channel and coherence of each pair, Welch-averaged in bounded "
                                   "memory (segments with lost samples skipped), plotted log-log as octave-band "
                                   "averages plus the points above 3x their band's average (thesis App. A.8), "
                                   "and written to spectra.csv.")
    s.add_argument("file", metavar="FILE.h5", help="an fbs-run file")
    s.add_argument("--channels", required=True, help="comma-separated channel names, e.g. ac_x_ctl,gyro_x")
    s.add_argument("--out", metavar="DIR", help="output directory (default: next to FILE, FILE stem + '_spectra')")
    s.add_argument("--seg-s", type=float, metavar="S",
                   help="Welch segment length in seconds (default: a power of two of samples near 10 s, "
                        "shorter if the run holds fewer than 8 such segments)")
    s.set_defaults(func=_run)
    return s
