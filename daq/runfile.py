"""The "fbs-run" HDF5 layout, version 1 (DESIGN.md section 6), and a writer for it.

Root attributes ``format``, ``format_version``, ``created``, ``rig``, ``mode`` and optionally
``axis``, ``procedure``, ``status``; group ``/channels`` with one 1-D float dataset per
channel (attributes ``units``, ``sample_rate_hz``), all on one time base from t = 0; optional
``/events`` (time, kind, text) and ``/meta`` (JSON strings). Readable with plain h5py.

The writer appends blocks to chunked, resizable datasets and always leaves a status: a run
that ends by an exception is closed "aborted: <why>".
"""

from __future__ import annotations

import datetime as _dt
import json
import logging
from pathlib import Path
from types import TracebackType
from typing import Any, Mapping

import h5py
import numpy as np

from fbs import __version__

log = logging.getLogger(__name__)

FORMAT = "fbs-run"
FORMAT_VERSION = 1
EVENT_DTYPE = np.dtype([("time", "f8"), ("kind", h5py.string_dtype()), ("text", h5py.string_dtype())])


class RunFileError(OSError):
    """The run file cannot be created or written; the message says where and why."""


class RunWriter:
    """Append-only writer of one run file. Use as a context manager."""

    def __init__(self, path: str | Path, *, rig: str, mode: int, rate_hz: float,
                 channels: Mapping[str, str], axis: str | None = None, procedure: str | None = None,
                 meta: Mapping[str, Any] | None = None, chunk: int = 4096) -> None:
        self.path = Path(path)
        self.rate_hz = float(rate_hz)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.f = h5py.File(self.path, "w")
        except OSError as exc:
            raise RunFileError(f"cannot create run file {self.path}: {exc}") from exc
        a = self.f.attrs
        a["format"] = FORMAT
        a["format_version"] = FORMAT_VERSION
        a["created"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
        a["rig"] = rig
        a["mode"] = int(mode)
        a["status"] = "recording"
        if axis is not None:
            a["axis"] = axis
        if procedure is not None:
            a["procedure"] = procedure
        g = self.f.create_group("channels")
        self.datasets = {}
        for name, units in channels.items():
            ds = g.create_dataset(name, shape=(0,), maxshape=(None,), dtype="f8", chunks=(chunk,))
            ds.attrs["units"] = units
            ds.attrs["sample_rate_hz"] = self.rate_hz
            self.datasets[name] = ds
        self.events = self.f.create_dataset("events", shape=(0,), maxshape=(None,), dtype=EVENT_DTYPE,
                                            chunks=(256,))
        m = self.f.create_group("meta")
        m.attrs["software_version"] = json.dumps({"fbs-hil": __version__})
        for k, v in (meta or {}).items():
            m.attrs[k] = json.dumps(v)
        self.n = 0

    def append(self, columns: Mapping[str, np.ndarray]) -> None:
        """Append one block: every channel of the file, equal lengths."""
        lengths = {len(v) for v in columns.values()}
        if set(columns) != set(self.datasets) or len(lengths) != 1:
            raise ValueError("a block must hold every channel of the run, all of one length")
        n = lengths.pop()
        try:
            for name, ds in self.datasets.items():
                ds.resize((self.n + n,))
                ds[self.n:] = columns[name]
        except OSError as exc:
            raise RunFileError(f"writing {self.path} failed (disk full or removed?): {exc}") from exc
        self.n += n

    def event(self, time_s: float, kind: str, text: str) -> None:
        k = len(self.events)
        self.events.resize((k + 1,))
        self.events[k] = (time_s, kind, text)

    def close(self, status: str = "complete") -> None:
        if not self.f.id.valid:
            return
        self.f.attrs["status"] = status
        self.f.close()

    def __enter__(self) -> "RunWriter":
        return self

    def __exit__(self, et: type | None, ev: BaseException | None, tb: TracebackType | None) -> None:
        if ev is None:
            self.close("complete")
        else:
            why = "interrupted" if isinstance(ev, KeyboardInterrupt) else f"{type(ev).__name__}: {ev}"
            self.close(f"aborted: {why}")


def read_channels(path: str | Path, names: list[str] | None = None) -> tuple[dict[str, np.ndarray], float]:
    """Whole channels of a run file, and the common sample rate."""
    with h5py.File(path, "r") as f:
        if f.attrs.get("format") != FORMAT:
            raise RunFileError(f"{path} is not an {FORMAT} file (format = {f.attrs.get('format')!r})")
        g = f["channels"]
        names = list(g) if names is None else names
        missing = [n for n in names if n not in g]
        if missing:
            raise RunFileError(f"{path} lacks channel(s) {', '.join(missing)} (has {', '.join(g)})")
        data = {n: g[n][()] for n in names}
        rates = {float(g[n].attrs["sample_rate_hz"]) for n in names}
    if len(rates) != 1:
        raise RunFileError(f"{path}: channels have different sample rates {sorted(rates)}")
    return data, rates.pop()
