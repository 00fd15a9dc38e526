"""``fbs record [--rig URL] --mode M --duration S --rate HZ [--channels a,b] --out FILE.h5 [--json]``:
the rig's ADC channels into one fbs-run file (DESIGN.md section 7).

Every argument and ``--out`` are checked before the rig is told anything. ``--json`` prints one
object instead of the summary line: ``file``, ``mode``, ``rate_hz``, ``n_samples``,
``duration_s``, ``status``, ``channels``, ``lost`` (samples), ``gaps``
[{``start``, ``stop``, ``reason``}] (sample positions, stop exclusive), ``rig_safe_at_close``
(bool) and ``rig_safe_detail``. A safe state not read back when the rig closed exits 2 with the
file whole, and the file's root attribute ``rig_safe_at_close`` says so.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from drivers.rig_datasheet import ADC_CHANNELS
from fbs import jsonout
from fbs.usage import EXIT_ERROR

#: DESIGN.md section 5 names 19 channels: a recording's disk check assumes all of them unless
#: --channels names fewer
ALL_CHANNELS = len(ADC_CHANNELS)
#: no ADC this software drives streams more sample sets per second (the sim's: 2 MS/s shared);
#: the ADC itself refuses, with its own limit, a rate it cannot keep up for the channels asked
MAX_RECORD_RATE_HZ = 2_000_000.0


def json_result(args: argparse.Namespace) -> dict[str, Any]:
    """Record as asked; the object ``--json`` prints."""
    from daq.reader import RunFile
    from daq.recorder import record
    from daq.runfile import check_request, set_root_attr
    from drivers.rig import open_rig

    channels = [c for c in args.channels.split(",") if c] if args.channels else None
    check_request(
        args.out,
        duration_s=args.duration,
        rate_hz=args.rate,
        max_rate_hz=MAX_RECORD_RATE_HZ,
        n_channels=len(channels) if channels else ALL_CHANNELS,
    )
    rig = open_rig(args.rig)
    try:
        rig.set_mode(args.mode)  # disallowed modes and interlocks are refused here, with the reason
        result = record(
            rig, args.out, duration_s=args.duration, rate_hz=args.rate, channels=channels
        )
    finally:
        report = rig.close()
    # the rig's end is part of the run's record: a safe state not read back is said in the file too
    safe = report is None or report.ok
    safe_text = (
        "read back" if safe else "NOT confirmed: " + "; ".join(report.failed if report else [])
    )
    set_root_attr(result.path, "rig_safe_at_close", safe_text)
    with RunFile(result.path) as run:
        recorded = list(run.channels)
    return {
        "file": str(result.path),
        "mode": args.mode,
        "rate_hz": result.rate_hz,
        "n_samples": result.samples,
        "duration_s": result.samples / result.rate_hz,
        "status": result.status,
        "channels": recorded,
        "lost": result.lost,
        "gaps": [{"start": a, "stop": b, "reason": why} for a, b, why in result.gaps],
        "rig_safe_at_close": safe,
        "rig_safe_detail": safe_text,
    }


def _record(args: argparse.Namespace) -> int:
    result = json_result(args)
    unsafe = not result["rig_safe_at_close"]
    if args.json:
        print(jsonout.dumps(result))
    else:
        lost = (
            f", {result['lost']} samples lost in {len(result['gaps'])} gap(s)"
            if result["gaps"]
            else ""
        )
        print(
            f"wrote {result['file']}: mode {args.mode}, {result['n_samples']} samples at {result['rate_hz']:g} Hz, "
            f"status {result['status']}{lost}"
        )
    if unsafe:  # the recording is whole; the rig's state is not known: exit 2, said on stderr
        print(
            f"fbs record: error: the rig's safe state was not read back at the end "
            f"({result['rig_safe_detail']}); check the rig before anyone works on it",
            file=sys.stderr,
        )
        return EXIT_ERROR
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    r = sub.add_parser("record", help="record the rig's ADC channels to an fbs-run file")
    r.add_argument("--rig", default="sim", help="rig URL (default: the simulated rig, 'sim')")
    r.add_argument(
        "--mode",
        type=int,
        required=True,
        help="mode to record in: 1, 2, 3 or 6 (mode 3 cages once the wheels are at speed). 4 and 5 "
        "need the gyros at speed and caged before the command starts, which a real rig never is "
        "(every command ends in mode 1): the interlock refuses them at once, naming what is "
        "missing; the sim's warm start (sim?warm=1) allows them",
    )
    r.add_argument("--duration", type=float, required=True, help="seconds")
    r.add_argument("--rate", type=float, required=True, help="sample rate per channel, Hz")
    r.add_argument("--channels", help="comma-separated channel names (default: all)")
    r.add_argument("--out", required=True, help="output .h5 file")
    r.add_argument(
        "--json",
        action="store_true",
        help="one JSON object on stdout: file, mode, rate_hz, n_samples, "
        "duration_s, status, channels, lost samples and gaps",
    )
    r.set_defaults(func=_record, json_result=json_result)
