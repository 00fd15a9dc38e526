"""``fbs inspect FILE`` and ``fbs recover FILE``: what a run file holds, and repairing one
whose writer died.

``inspect`` reads only attributes, dataset shapes and the events, so it is instant on a
file of any size, and it works on a file being recorded (SWMR) or left by a killed writer.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from daq.reader import RunFile
from daq.recover import recover
from daq.runfile import STATUS_RECORDING

MAX_EVENTS = 200


def describe(path: str | Path, max_events: int = MAX_EVENTS) -> list[str]:
    """The lines ``fbs inspect`` prints."""
    with RunFile(path) as run:
        a = run.attrs
        lines = [f"{run.path}: {a.get('format')} version {a.get('format_version')}, created {a.get('created', '?')}"]
        ident = [f"rig {a.get('rig', '?')}", f"mode {a.get('mode', '?')}"]
        ident += [f"{k} {a[k]}" for k in ("axis", "procedure") if k in a]
        lines.append("  " + ", ".join(ident))
        lines.append(f"  status: {run.status}")
        if "writer" in a:
            alive = {True: "still running", False: "gone", None: "on another host"}[run.writer_alive()]
            lines.append(f"  writer: {a['writer']} ({alive})" if a.get("status") == STATUS_RECORDING
                         else f"  writer: {a['writer']}")
        if run.swmr:
            lines.append("  opened in SWMR mode: the file is open for writing, or its writer died "
                         "(`fbs recover` then makes it open with plain h5py)")
        lines.append(f"  rate {run.rate_hz:g} Hz, {run.n_samples} samples, duration {run.duration_s:.3f} s")
        lengths = run.lengths
        lines.append(f"  channels ({len(run.channels)}):")
        width = max(len(c) for c in run.channels)
        for c in run.channels:
            extra = f"  ({lengths[c]} samples)" if lengths[c] != run.n_samples else ""
            lines.append(f"    {c:<{width}}  {run.units[c] or '-'}{extra}")
        events = run.events
        lines.append(f"  events ({len(events)}):")
        for e in events[:max_events]:
            lines.append(f"    {e.time_s:12.4f} s  {e.kind:<10} {e.text}")
        if len(events) > max_events:
            lines.append(f"    ... {len(events) - max_events} more")
        meta = run.meta
        if meta:
            lines.append("  meta: " + ", ".join(f"{k} ({len(json.dumps(v))} bytes)" for k, v in meta.items()))
    return lines


def _inspect(args: argparse.Namespace) -> int:
    print("\n".join(describe(args.file, args.max_events)))
    return 0


def _recover(args: argparse.Namespace) -> int:
    print(recover(args.file, force=args.force).summary())
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    i = sub.add_parser("inspect", help="channels, units, rate, duration, status and events of a run file")
    i.add_argument("file")
    i.add_argument("--max-events", type=int, default=MAX_EVENTS, help="events to list (default %(default)s)")
    i.set_defaults(func=_inspect)
    r = sub.add_parser("recover", help="make a run file left by a killed writer open with plain h5py again")
    r.add_argument("file")
    r.add_argument("--force", action="store_true", help="even if a process with the writer's pid runs")
    r.set_defaults(func=_recover)
