"""``fbs inspect FILE`` and ``fbs recover FILE``: what a run file holds, and repairing one
whose writer died.

``inspect`` reads only attributes, dataset shapes and the events, so it is instant on a
file of any size, and it works on a file being recorded (SWMR) or left by a killed writer.

A file that breaks the layout contract (``daq.reader``: DESIGN.md section 6) is still shown as
far as HDF5 reads it - root attributes, and each member of ``/channels`` with its type, shape,
units and rate - followed by every rule it breaks; the command then ends as an error (exit 2,
``fbs inspect: error: <the rules>`` on stderr), as the analysis commands do on that file. A
path that is not a readable HDF5 file (a FIFO, a directory, truncated) is only the error.
``--json`` prints ``summary``'s object instead (a broken file: only the error).

``recover --json`` prints ``recovery_json``'s object instead of the summary line.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fbs import jsonout

if TYPE_CHECKING:  # h5py, numpy and the reader load when the command runs, not with the parser
    import h5py

    from daq.recover import Recovery

MAX_EVENTS = 200
#: members of /channels (and root attributes) a broken file's description lists
MAX_LISTED = 64


def describe(path: str | Path, max_events: int = MAX_EVENTS) -> list[str]:
    """The lines ``fbs inspect`` prints."""
    from daq.reader import RunFile
    from daq.runfile import STATUS_RECORDING

    with RunFile(path) as run:
        a = run.attrs
        lines = [
            f"{run.path}: {a.get('format')} version {a.get('format_version')}, created {a.get('created', '?')}"
        ]
        ident = [f"rig {a.get('rig', '?')}", f"mode {a.get('mode', '?')}"]
        ident += [f"{k} {a[k]}" for k in ("axis", "procedure") if k in a]
        lines.append("  " + ", ".join(ident))
        lines.append(f"  status: {run.status}")
        if "writer" in a:
            alive = {True: "still running", False: "gone", None: "on another host"}[
                run.writer_alive()
            ]
            lines.append(
                f"  writer: {a['writer']} ({alive})"
                if a.get("status") == STATUS_RECORDING
                else f"  writer: {a['writer']}"
            )
        if run.swmr:
            lines.append(
                "  opened in SWMR mode: the file is open for writing, or its writer died "
                "(`fbs recover` then makes it open with plain h5py)"
            )
        lines.append(
            f"  rate {run.rate_hz:g} Hz, {run.n_samples} samples, duration {run.duration_s:.3f} s"
        )
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
            lines.append(
                "  meta: " + ", ".join(f"{k} ({len(json.dumps(v))} bytes)" for k, v in meta.items())
            )
    return lines


def _value(v: Any) -> str:
    from daq.reader import as_text

    if isinstance(v, (bytes, str)):
        v = as_text(v)
    text = repr(v) if isinstance(v, str) else str(v).replace("\n", " ")
    return text if len(text) <= 60 else text[:57] + "..."


def _attrs(obj: Any, names: tuple[str, ...] | None = None) -> str:
    out = []
    for k in (
        list(obj.attrs)[:MAX_LISTED] if names is None else [n for n in names if n in obj.attrs]
    ):
        try:
            out.append(f"{k} {_value(obj.attrs[k])}")
        except (OSError, RuntimeError, TypeError, ValueError) as exc:
            out.append(f"{k} <unreadable: {exc}>")
    return ", ".join(out) or "none"


def _member_line(g: h5py.Group, name: str) -> str:
    import h5py

    link = g.get(name, getlink=True)
    if isinstance(link, (h5py.ExternalLink, h5py.SoftLink)):
        target = (
            f"{link.filename}:{link.path}" if isinstance(link, h5py.ExternalLink) else link.path
        )
        kind = f"{type(link).__name__} to {target}"
        if isinstance(link, h5py.ExternalLink):  # not followed: the other file is not this one's
            return kind
        obj = g.get(name)
        if obj is None:
            return f"{kind} (dangling)"
        kind += ", "
    else:
        kind, obj = "", g[name]
    if isinstance(obj, h5py.Dataset):
        try:
            dtype = str(obj.dtype)
        except (TypeError, ValueError) as exc:
            dtype = f"<type unreadable: {exc}>"
        return (
            f"{kind}dataset {dtype} shape {obj.shape}; {_attrs(obj, ('units', 'sample_rate_hz'))}"
        )
    return f"{kind}{'group' if isinstance(obj, h5py.Group) else type(obj).__name__}"


def describe_broken(path: str | Path, problems: tuple[str, ...]) -> list[str]:
    """The lines ``fbs inspect`` prints for a file that breaks the layout contract: what HDF5
    reads of it, then each rule broken."""
    import h5py

    from daq.reader import as_text, open_hdf5

    lines = [
        f"{path}: HDF5, but not a valid fbs-run version 1 file (the rules it breaks are listed below)"
    ]
    try:
        f, _swmr = open_hdf5(path)
    except OSError as exc:
        lines.append(f"  (cannot be opened again to describe it: {exc})")
    else:
        try:
            with f:
                lines.append(f"  root attributes: {_attrs(f)}")
                link = f.get("channels", getlink=True)
                g = None if isinstance(link, h5py.ExternalLink) else f.get("channels")
                if isinstance(g, h5py.Group):
                    names = list(g)
                    lines.append(f"  /channels ({len(names)} members):")
                    width = max([len(as_text(c)) for c in names[:MAX_LISTED]] + [1])
                    for c in names[:MAX_LISTED]:
                        try:
                            lines.append(f"    {as_text(c):<{width}}  {_member_line(g, c)}")
                        except (OSError, RuntimeError, KeyError, TypeError, ValueError) as exc:
                            lines.append(f"    {as_text(c):<{width}}  <unreadable: {exc}>")
                    if len(names) > MAX_LISTED:
                        lines.append(f"    ... {len(names) - MAX_LISTED} more")
                others = [k for k in f if k != "channels"]
                if others:
                    lines.append(
                        "  other members: "
                        + ", ".join(
                            f"/{k} ({_member_line(f, k).split(';')[0]})"
                            for k in others[:MAX_LISTED]
                        )
                    )
        except (OSError, RuntimeError, KeyError, TypeError, ValueError) as exc:
            lines.append(f"  (the rest cannot be read: {exc})")
    lines.append("  breaks the layout contract:")
    lines += [f"    - {p}" for p in problems]
    return lines


def _plain(v: Any) -> Any:
    """An attribute value as JSON: text decoded, numpy scalars and arrays as Python's."""
    import numpy as np

    from daq.reader import as_text

    if isinstance(v, (bytes, str)):
        return as_text(v)
    if isinstance(v, np.generic):
        return _plain(v.item())
    if isinstance(v, np.ndarray):
        return _plain(v.tolist())
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if v is None or isinstance(v, (bool, int, float)):
        return v
    return as_text(str(v))


def summary(path: str | Path, max_events: int = MAX_EVENTS) -> dict[str, Any]:
    """What ``fbs inspect --json`` prints: the file's root ``attrs``, its ``status`` as read (a
    "recording" file whose writer is gone reads as aborted), ``swmr``, ``rate_hz``,
    ``n_samples``, ``duration_s``, ``channels`` {name: {``units``, ``samples``}}, the first
    ``max_events`` ``events`` [{``time_s``, ``kind``, ``text``}] of ``events_total``, and the
    names of its ``meta`` entries. A file that breaks the layout contract raises ``ContractError``."""
    from daq.reader import RunFile

    with RunFile(path) as run:
        lengths = run.lengths
        events = run.events
        return {
            "file": str(run.path),
            "attrs": {k: _plain(v) for k, v in run.attrs.items()},
            "status": run.status,
            "swmr": run.swmr,
            "rate_hz": run.rate_hz,
            "n_samples": run.n_samples,
            "duration_s": run.duration_s,
            "channels": {c: {"units": run.units[c], "samples": lengths[c]} for c in run.channels},
            "events": [
                {"time_s": e.time_s, "kind": e.kind, "text": e.text} for e in events[:max_events]
            ],
            "events_total": len(events),
            "meta": sorted(run.meta),
        }


def _max_events(args: argparse.Namespace) -> int:
    if args.max_events < 0:
        raise ValueError(
            f"--max-events {args.max_events} must be >= 0 (0 lists none, only the count)"
        )
    return int(args.max_events)


def json_result(args: argparse.Namespace) -> dict[str, Any]:
    """The object ``--json`` prints (``fbs batch inspect`` collects the same)."""
    return summary(args.file, _max_events(args))


def _inspect(args: argparse.Namespace) -> int:
    from daq.contract import ContractError

    if args.json:  # a broken file is only the error (exit 2), stdout stays empty
        print(jsonout.dumps(json_result(args)))
        return 0
    try:
        lines = describe(args.file, _max_events(args))
    except (
        ContractError
    ) as exc:  # shown as far as it reads, then an error (exit 2) naming the rules
        print("\n".join(describe_broken(args.file, exc.problems)))
        raise
    print("\n".join(lines))
    return 0


def recovery_json(r: Recovery) -> dict[str, Any]:
    """What ``fbs recover --json`` prints: ``file``, ``was_open`` (false: closed properly,
    nothing done), ``n_samples`` per channel kept, ``rate_hz``, ``duration_s``, ``padded``
    {channel: NaN samples added} and ``status``."""
    return {
        "file": str(r.path),
        "was_open": r.was_open,
        "n_samples": r.samples,
        "rate_hz": r.rate_hz,
        "duration_s": r.samples / r.rate_hz if r.rate_hz else None,
        "padded": dict(r.padded),
        "status": r.status,
    }


def recover_json_result(args: argparse.Namespace) -> dict[str, Any]:
    """Recover the file; the object ``--json`` prints."""
    from daq.recover import recover

    return recovery_json(recover(args.file, force=args.force))


def _recover(args: argparse.Namespace) -> int:
    from daq.recover import recover

    r = recover(args.file, force=args.force)
    print(jsonout.dumps(recovery_json(r)) if args.json else r.summary())
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    i = sub.add_parser(
        "inspect", help="channels, units, rate, duration, status and events of a run file"
    )
    i.add_argument("file")
    i.add_argument(
        "--max-events", type=int, default=MAX_EVENTS, help="events to list (default %(default)s)"
    )
    i.add_argument(
        "--json",
        action="store_true",
        help="one JSON object on stdout: attributes, status, rate, "
        "samples, duration, channels with units, events, meta names",
    )
    i.set_defaults(func=_inspect, json_result=json_result)
    r = sub.add_parser(
        "recover", help="make a run file left by a killed writer open with plain h5py again"
    )
    r.add_argument("file")
    r.add_argument(
        "--force", action="store_true", help="even if a process with the writer's pid runs"
    )
    r.add_argument(
        "--json",
        action="store_true",
        help="one JSON object on stdout: file, was_open, n_samples, "
        "rate_hz, duration_s, padded, status",
    )
    r.set_defaults(func=_recover, json_result=recover_json_result)
