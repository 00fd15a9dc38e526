"""``fbs spectra FILE.h5 --channels a,b [--out DIR] [--seg-s S] [--json]`` (DESIGN.md section 7).

The numerics and the files written are ``procedures.analysis.channel_spectra``'s; this is the command line.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fbs import jsonout

if TYPE_CHECKING:
    from procedures.analysis.channel_spectra import SpectraResult


def _compute(args: argparse.Namespace) -> SpectraResult:
    # the numerics load when the command runs, not with the parser (`fbs --version`)
    from procedures.analysis.channel_spectra import default_out_dir, spectra_command

    channels = [c for c in args.channels.split(",") if c.strip()]
    out = Path(args.out) if args.out else default_out_dir(args.file)
    return spectra_command(args.file, channels, out, seg_s=args.seg_s)


def summary(result: SpectraResult) -> dict[str, Any]:
    """What ``--json`` prints: the files written, the Welch estimate's segments, resolution and
    EDOF, and per channel its octave-band count, PSD units and the points kept above
    ``KEEP_FACTOR`` times their band's average (``kept_f_hz``, ``kept_psd``), the plots' content."""
    from daq.plots import psd_units_label

    c = result.csd
    return {
        "file": str(result.path),
        "out_dir": str(result.out_dir),
        "files": [str(p) for p in result.files],
        "rate_hz": float(c.fs),
        "n_samples": int(c.n_samples),
        "segment_samples": int(c.nperseg),
        "segment_s": float(c.segment_s),
        "overlap_samples": int(c.noverlap),
        "resolution_hz": float(c.resolution_hz),
        "segments_used": int(c.segments_used),
        "segments_total": int(c.segments_total),
        "segments_skipped": int(c.segments_skipped),
        "dof": float(c.dof),
        "channels": {
            ch: {
                "psd_units": psd_units_label(c.units[c.index(ch)], c.scaling),
                "octave_bands": int(b.n_bands),
                "keep_factor": float(b.factor),
                "kept_f_hz": [float(f) for f in b.kept_f],
                "kept_psd": [float(p) for p in b.kept_p],
            }
            for ch, b in result.bands.items()
        },
    }


def json_result(args: argparse.Namespace) -> dict[str, Any]:
    """The object ``--json`` prints (``fbs batch spectra`` collects the same)."""
    return summary(_compute(args))


def _run(args: argparse.Namespace) -> int:
    if args.json:
        print(jsonout.dumps(json_result(args)))
        return 0
    result = _compute(args)
    for p in result.files:
        print(f"wrote {p}")
    for line in result.lines():
        print(line)
    return 0


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``spectra`` on the ``fbs`` subcommands (``sub`` from ``add_subparsers``)."""
    s = sub.add_parser(
        "spectra",
        help="PSD and coherence plots of a run file (App. A.8 octave bands)",
        description="PSD of each channel and coherence of each pair, Welch-averaged in bounded "
        "memory (segments with lost samples skipped), plotted log-log as octave-band "
        "averages plus the points above 3x their band's average (thesis App. A.8), "
        "and written to spectra.csv.",
    )
    s.add_argument("file", metavar="FILE.h5", help="an fbs-run file")
    s.add_argument(
        "--channels", required=True, help="comma-separated channel names, e.g. ac_x_ctl,gyro_x"
    )
    s.add_argument(
        "--out",
        metavar="DIR",
        help="output directory (default: next to FILE, FILE stem + '_spectra')",
    )
    s.add_argument(
        "--seg-s",
        type=float,
        metavar="S",
        help="Welch segment length in seconds (default: a power of two of samples near 10 s, "
        "shorter if the run holds fewer than 8 such segments)",
    )
    s.add_argument(
        "--json",
        action="store_true",
        help="one JSON object on stdout (files written, segments, "
        "resolution, EDOF, the points kept above their band's average) instead of the summary lines",
    )
    s.set_defaults(func=_run, json_result=json_result)
    return s
