"""``fbs record [--rig URL] --mode M --duration S --rate HZ [--channels a,b] --out FILE.h5 [--json]``:
the rig's ADC channels into one fbs-run file (DESIGN.md section 7).

Every argument and ``--out`` are checked before the rig is told anything. ``--json`` prints one
object instead of the summary line: ``file``, ``mode``, ``rate_hz``, ``n_samples``,
``duration_s``, ``status``, ``channels``, ``lost`` (samples) and ``gaps``
[{``start``, ``stop``, ``reason``}] (sample positions, stop exclusive).
"""

from __future__ import annotations

import argparse
import json
from typing import Any

#: DESIGN.md section 5 names 20 channels: a recording's disk check assumes all of them unless
#: --channels names fewer
ALL_CHANNELS = 20
#: no ADC this software drives streams more sample sets per second (the sim's: 2 MS/s shared);
#: the ADC itself refuses, with its own limit, a rate it cannot keep up for the channels asked
MAX_RECORD_RATE_HZ = 2_000_000.0


def json_result(args: argparse.Namespace) -> dict[str, Any]:
    """Record as asked; the object ``--json`` prints."""
    from daq.reader import RunFile
    from daq.recorder import record
    from daq.runfile import check_request
    from drivers.rig import open_rig

    channels = [c for c in args.channels.split(",") if c] if args.channels else None
    check_request(args.out, duration_s=args.duration, rate_hz=args.rate, max_rate_hz=MAX_RECORD_RATE_HZ,
                  n_channels=len(channels) if channels else ALL_CHANNELS)
    with open_rig(args.rig) as rig:
        rig.set_mode(args.mode)  # disallowed modes and interlocks are refused here, with the reason
        result = record(rig, args.out, duration_s=args.duration, rate_hz=args.rate, channels=channels)
    with RunFile(result.path) as run:
        recorded = list(run.channels)
    return {"file": str(result.path), "mode": args.mode, "rate_hz": result.rate_hz, "n_samples": result.samples,
            "duration_s": result.samples / result.rate_hz, "status": result.status, "channels": recorded,
            "lost": result.lost, "gaps": [{"start": a, "stop": b, "reason": why} for a, b, why in result.gaps]}


def _record(args: argparse.Namespace) -> int:
    result = json_result(args)
    if args.json:
        print(json.dumps(result))
        return 0
    lost = f", {result['lost']} samples lost in {len(result['gaps'])} gap(s)" if result["gaps"] else ""
    print(f"wrote {result['file']}: mode {args.mode}, {result['n_samples']} samples at {result['rate_hz']:g} Hz, "
          f"status {result['status']}{lost}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    r = sub.add_parser("record", help="record the rig's ADC channels to an fbs-run file")
    r.add_argument("--rig", default="sim", help="rig URL (default: the simulated rig, 'sim')")
    r.add_argument("--mode", type=int, required=True, help="mode to record in (1-6; the rig checks interlocks)")
    r.add_argument("--duration", type=float, required=True, help="seconds")
    r.add_argument("--rate", type=float, required=True, help="sample rate per channel, Hz")
    r.add_argument("--channels", help="comma-separated channel names (default: all)")
    r.add_argument("--out", required=True, help="output .h5 file")
    r.add_argument("--json", action="store_true", help="one JSON object on stdout: file, mode, rate_hz, n_samples, "
                   "duration_s, status, channels, lost samples and gaps")
    r.set_defaults(func=_record, json_result=json_result)
