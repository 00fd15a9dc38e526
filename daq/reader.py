"""Reading "fbs-run" files (DESIGN.md section 6) in bounded memory.

``RunFile`` opens any file that follows the contract, whoever wrote it, and gives

* lazy channel arrays (``run.channel("X")[a:b]`` reads only that slice from disk),
* time slices (``run.slice_s(10.0, 20.0)``),
* block iteration (``run.blocks(block_s=1.0, overlap=...)``) whose memory is one block,
* the events, ``/meta`` decoded from JSON, and the run's status.

A file a live writer holds in SWMR mode, or one a killed writer left behind, is opened
read-only in SWMR mode; ``refresh()`` then picks up what the writer has flushed since.
"""

from __future__ import annotations

import json
import logging
import os
import re
import socket
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, overload

import h5py
import numpy as np

from daq.runfile import FORMAT, STATUS_RECORDING, RunFileError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Event:
    time_s: float
    kind: str
    text: str


@dataclass(frozen=True)
class Block:
    """Samples ``start .. start + n`` of some channels, one row per channel."""

    start: int
    rate_hz: float
    channels: tuple[str, ...]
    data: np.ndarray                         # (n_channels, n)

    def __len__(self) -> int:
        return self.data.shape[1]

    def __getitem__(self, channel: str) -> np.ndarray:
        return self.data[self.channels.index(channel)]

    @property
    def stop(self) -> int:
        return self.start + len(self)

    @property
    def time_s(self) -> np.ndarray:
        return (self.start + np.arange(len(self))) / self.rate_hz


class Channel:
    """One channel as a lazy 1-D array: ``len``, slicing and ``np.asarray`` read from disk."""

    def __init__(self, run: RunFile, name: str) -> None:
        self.run, self.name = run, name
        self._ds = run._group[name]
        self.units = _text(self._ds.attrs.get("units", ""))
        self.rate_hz = run.rate_hz

    def __len__(self) -> int:
        return self.run.n_samples

    @overload
    def __getitem__(self, index: slice) -> np.ndarray: ...

    @overload
    def __getitem__(self, index: int) -> float: ...

    def __getitem__(self, index: slice | int) -> np.ndarray | float:
        if isinstance(index, slice):
            start, stop, step = index.indices(len(self))
            if step != 1:
                return self._ds[start:stop][::step]
            return self._ds[start:stop] if stop > start else np.empty(0)
        n = len(self)
        i = index + n if index < 0 else index
        if not 0 <= i < n:
            raise IndexError(f"sample {index} outside channel {self.name} of {n} samples")
        return float(self._ds[i])

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        a = self[:]
        return a if dtype is None else a.astype(dtype)

    def __repr__(self) -> str:
        return f"<Channel {self.name} [{self.units}] {len(self)} samples at {self.rate_hz:g} Hz>"


def _text(v: Any) -> str:
    return v.decode("utf-8", errors="replace") if isinstance(v, bytes) else str(v)


def _open(path: Path) -> tuple[h5py.File, bool]:
    """Open plain read-only; a file still marked open for writing (a live SWMR writer, or
    one that was killed) is opened in SWMR-read mode instead. Returns (file, swmr)."""
    if not path.exists():
        raise RunFileError(f"{path}: no such file")
    try:
        return h5py.File(path, "r"), False
    except OSError as exc:
        if "truncated file" in str(exc):
            raise RunFileError(f"cannot open {path}: its writer failed while extending it (disk full?): {exc}; "
                               f"`fbs recover {path}` repairs it") from exc
        if "already open for write" not in str(exc) and "unable to lock" not in str(exc).lower():
            raise RunFileError(f"cannot open {path}: {exc}") from exc
    try:
        return h5py.File(path, "r", swmr=True), True
    except OSError as exc:
        raise RunFileError(f"cannot open {path} (held by a writer, or left by one that died): {exc}") from exc


class RunFile:
    """An open run file. Use as a context manager."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.f, self.swmr = _open(self.path)
        try:
            self._check()
        except BaseException:
            self.f.close()
            raise

    def _check(self) -> None:
        fmt = _text(self.f.attrs.get("format", ""))
        if fmt != FORMAT:
            raise RunFileError(f"{self.path} is not an {FORMAT} file (format = {fmt!r})")
        if "channels" not in self.f:
            raise RunFileError(f"{self.path} has no /channels group")
        self._group = self.f["channels"]
        self.channels: tuple[str, ...] = tuple(self._group)
        if not self.channels:
            raise RunFileError(f"{self.path} has no channels")
        rates = {}
        for c in self.channels:
            ds = self._group[c]
            if ds.ndim != 1:
                raise RunFileError(f"{self.path}: channel {c} is {ds.ndim}-D, the layout needs 1-D")
            if "sample_rate_hz" not in ds.attrs:
                raise RunFileError(f"{self.path}: channel {c} has no sample_rate_hz attribute")
            rates[c] = float(ds.attrs["sample_rate_hz"])
        if len(set(rates.values())) != 1:
            raise RunFileError(f"{self.path}: channels have different sample rates {rates}")
        self.rate_hz = rates[self.channels[0]]
        if not self.rate_hz > 0:
            raise RunFileError(f"{self.path}: sample_rate_hz = {self.rate_hz} is not positive")
        self.units = {c: _text(self._group[c].attrs.get("units", "")) for c in self.channels}

    # ------------------------------------------------------------------ description
    @property
    def attrs(self) -> dict[str, Any]:
        return {k: (_text(v) if isinstance(v, (bytes, str)) else v) for k, v in self.f.attrs.items()}

    @property
    def n_samples(self) -> int:
        """Samples every channel holds (a live writer may be between channels)."""
        return min(self._group[c].shape[0] for c in self.channels)

    @property
    def lengths(self) -> dict[str, int]:
        return {c: self._group[c].shape[0] for c in self.channels}

    @property
    def duration_s(self) -> float:
        return self.n_samples / self.rate_hz

    @property
    def status(self) -> str:
        """The root ``status``; a "recording" file whose writer is gone reads as aborted."""
        s = _text(self.f.attrs.get("status", ""))
        if s == STATUS_RECORDING and self.writer_alive() is False:
            return "aborted: the writer died without closing the file (run `fbs recover` on it)"
        return s

    def writer_alive(self) -> bool | None:
        """Whether the process that wrote the file still runs (None: cannot tell)."""
        return writer_alive(_text(self.f.attrs.get("writer", "")))

    @property
    def events(self) -> list[Event]:
        if "events" not in self.f:
            return []
        ds = self.f["events"]
        names = ds.dtype.names or ()
        if not {"time", "kind", "text"} <= set(names):
            raise RunFileError(f"{self.path}: /events lacks time, kind or text (has {names})")
        return [Event(float(r["time"]), _text(r["kind"]), _text(r["text"])) for r in ds[()]]

    @property
    def meta(self) -> dict[str, Any]:
        if "meta" not in self.f:
            return {}
        out = {}
        for k, v in self.f["meta"].attrs.items():
            try:
                out[k] = json.loads(_text(v))
            except (TypeError, ValueError):
                out[k] = _text(v)
        return out

    def refresh(self) -> None:
        """Pick up what a live SWMR writer has flushed since (no-op on a closed file)."""
        if not self.swmr:
            return
        for c in self.channels:
            self._group[c].refresh()
        if "events" in self.f:
            self.f["events"].refresh()

    # ------------------------------------------------------------------ data
    def channel(self, name: str) -> Channel:
        self._need([name])
        return Channel(self, name)

    def _need(self, names: Sequence[str]) -> None:
        missing = [n for n in names if n not in self.channels]
        if missing:
            raise RunFileError(f"{self.path} lacks channel(s) {', '.join(missing)} "
                               f"(has {', '.join(self.channels)})")

    def read(self, channels: Sequence[str] | None = None, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Samples ``start .. stop`` of ``channels`` (default all) as (n_channels, n)."""
        channels = list(self.channels if channels is None else channels)
        self._need(channels)
        n = self.n_samples
        stop = n if stop is None else stop
        if not 0 <= start <= stop <= n:
            raise ValueError(f"samples {start}..{stop} are outside {self.path} (0..{n})")
        # NaN, not np.empty: HDF5 leaves the buffer alone where a chunk was never written
        # (fill_time "never", or a writer that died between extending and writing)
        out = np.full((len(channels), stop - start), np.nan)
        for i, c in enumerate(channels):
            if stop > start:
                self._group[c].read_direct(out, np.s_[start:stop], np.s_[i, :])
        return out

    def slice_s(self, t0_s: float, t1_s: float, channels: Sequence[str] | None = None) -> Block:
        """The samples with t0_s <= t < t1_s (t = index / rate, from the start of the run)."""
        if not t1_s >= t0_s:
            raise ValueError(f"time slice {t0_s}..{t1_s} s is empty or reversed")
        n = self.n_samples
        a = min(n, max(0, int(np.ceil(t0_s * self.rate_hz - 1e-9))))
        b = min(n, max(a, int(np.ceil(t1_s * self.rate_hz - 1e-9))))
        channels = tuple(self.channels if channels is None else channels)
        return Block(a, self.rate_hz, channels, self.read(channels, a, b))

    def blocks(self, block_samples: int | None = None, *, block_s: float | None = None,
               channels: Sequence[str] | None = None, overlap: int = 0, start: int = 0,
               stop: int | None = None) -> Iterator[Block]:
        """Consecutive blocks of ``block_samples`` (or ``block_s``) samples, each starting
        ``block - overlap`` after the previous; the last may be shorter. One block in memory."""
        if (block_samples is None) == (block_s is None):
            raise ValueError("give exactly one of block_samples and block_s")
        if block_samples is not None:
            size = int(block_samples)
        else:
            assert block_s is not None  # exactly one of the two was given
            size = int(round(block_s * self.rate_hz))
        if size < 1 or not 0 <= overlap < size:
            raise ValueError(f"block of {size} samples with overlap {overlap}: need size >= 1, 0 <= overlap < size")
        channels = tuple(self.channels if channels is None else channels)
        self._need(channels)
        stop = self.n_samples if stop is None else min(stop, self.n_samples)
        pos = start
        while pos < stop:
            end = min(stop, pos + size)
            yield Block(pos, self.rate_hz, channels, self.read(channels, pos, end))
            if end == stop:
                break
            pos = end - overlap

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        self.f.close()

    def __enter__(self) -> RunFile:
        return self

    def __exit__(self, et: type | None, ev: BaseException | None, tb: TracebackType | None) -> None:
        self.close()


_WRITER = re.compile(r"pid (\d+) on (\S+)$")


def writer_alive(writer: str) -> bool | None:
    """From a ``writer`` attribute ("fbs-hil V, pid P on HOST"): is P alive here? None if the
    attribute does not say, or the host is another machine."""
    m = _WRITER.search(writer)
    if not m or m.group(2) != socket.gethostname():
        return None
    try:
        os.kill(int(m.group(1)), 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def read_channels(path: str | Path, names: list[str] | None = None) -> tuple[dict[str, np.ndarray], float]:
    """Whole channels of a run file (in memory), and the common sample rate."""
    with RunFile(path) as run:
        names = list(run.channels) if names is None else names
        data = run.read(names)
        return dict(zip(names, data)), run.rate_hz
