"""Reading "fbs-run" files (DESIGN.md section 6) in bounded memory.

``RunFile`` opens any file that follows the contract, whoever wrote it, and gives

* lazy channel arrays (``run.channel("X")[a:b]`` reads only that slice from disk),
* time slices (``run.slice_s(10.0, 20.0)``),
* block iteration (``run.blocks(block_s=1.0, overlap=...)``) whose memory is one block,
* the events, ``/meta`` decoded from JSON, and the run's status.

A file a live writer holds in SWMR mode, or one a killed writer left behind, is opened
read-only in SWMR mode; ``refresh()`` then picks up what the writer has flushed since.

Opening checks the layout contract (DESIGN.md section 6; ``daq.contract``, which lists its
rules) from metadata alone - no sample is read - and refuses a file that breaks it with a
``daq.contract.ContractError`` naming each rule broken and the bad value; a path that is not a
regular HDF5 file whose metadata reads is refused with an ``UnreadableRunFile`` before that.

Lost samples are NaN in a valid file (the recorder writes them so, with a ``gap`` event):
checking for them would read every sample, so opening does not; ``lost_samples`` describes
them where an analysis that cannot use them refuses.
"""

from __future__ import annotations

import json
import logging
import os
import re
import socket
import stat
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, overload

import h5py
import numpy as np

from daq.contract import ContractError, contract_error, contract_problems, events_problem
from daq.runfile import STATUS_RECORDING, RunFileError
from daq.swmr import open_swmr_read

log = logging.getLogger(__name__)

#: what a lost-samples message tells the reader about NaN in a run file
LOST_SAMPLES_NOTE = (
    "the recorder writes samples it lost as NaN and logs a `gap` event for them, "
    "which `fbs inspect FILE` lists"
)


class UnreadableRunFile(RunFileError):
    """Not a regular file, not HDF5, truncated, or metadata HDF5 cannot read."""


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
    data: np.ndarray  # (n_channels, n)

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
        self.units = as_text(self._ds.attrs.get("units", ""))
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


def as_text(v: Any) -> str:
    """Text for display: bytes decoded, and what is not UTF-8 (h5py gives undecodable bytes as lone
    surrogates) replaced, so that printing it cannot fail."""
    if isinstance(v, bytes):
        return v.decode("utf-8", errors="replace")
    return str(v).encode("utf-8", errors="surrogateescape").decode("utf-8", errors="replace")


def nonfinite_spans(x: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` of every run of non-finite samples (NaN, inf) in ``x``."""
    bad = ~np.isfinite(np.asarray(x))
    if not bad.any():
        return []
    d = np.diff(np.concatenate(([0], bad.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def spans_text(
    spans: Sequence[tuple[int, int]], rate_hz: float, offset: int = 0, max_spans: int = 3
) -> str:
    """The spans ``(start, stop)`` (``offset`` added) as "samples 500..509 (2.500..2.545 s), ..."."""
    shown = ", ".join(
        f"samples {offset + a}..{offset + b - 1} ({(offset + a) / rate_hz:.3f}..{(offset + b - 1) / rate_hz:.3f} s)"
        for a, b in spans[:max_spans]
    )
    return shown + (f" and {len(spans) - max_spans} more span(s)" if len(spans) > max_spans else "")


def lost_text(
    channel: str,
    spans: Sequence[tuple[int, int]],
    rate_hz: float,
    *,
    kinds: str | None = None,
    offset: int = 0,
    max_spans: int = 3,
) -> str:
    """The one wording every error uses for a channel's lost samples: the channel, the count
    (``kinds``, when the caller told NaN from inf; else "N lost (NaN/inf)") and the spans, e.g.
    "gyro_x has 10 lost (NaN/inf) samples: samples 500..509 (2.500..2.545 s)"."""
    kinds = kinds or f"{sum(b - a for a, b in spans)} lost (NaN/inf)"
    return f"{channel} has {kinds} samples: {spans_text(spans, rate_hz, offset, max_spans)}"


def lost_samples(
    channel: str, x: np.ndarray, rate_hz: float, offset: int = 0, max_spans: int = 3
) -> str | None:
    """None if every sample of ``x`` is finite; else ``lost_text`` with NaN and inf counted
    apart, e.g. "gyro_x has 10 lost (NaN) samples: samples 500..509 (2.500..2.545 s)"."""
    spans = nonfinite_spans(x)
    if not spans:
        return None
    x = np.asarray(x)
    n_nan = int(np.count_nonzero(np.isnan(x)))
    n_inf = int(np.count_nonzero(np.isinf(x)))
    kinds = " and ".join(
        k
        for k in (f"{n_nan} lost (NaN)" if n_nan else "", f"{n_inf} infinite" if n_inf else "")
        if k
    )
    return lost_text(channel, spans, rate_hz, kinds=kinds, offset=offset, max_spans=max_spans)


_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def check_regular_file(path: Path) -> None:
    """Refuse, without opening it, a path that is not a regular file: HDF5 would wait forever
    on a FIFO or a terminal for bytes no one writes."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise UnreadableRunFile(f"{path}: no such file") from None
    except OSError as exc:
        raise UnreadableRunFile(f"{path}: cannot look at it: {exc.strerror or exc}") from None
    if not stat.S_ISREG(mode):
        kind = next((k for test, k in _KINDS if test(mode)), f"not a regular file (mode {mode:o})")
        raise UnreadableRunFile(
            f"{path} is {kind}, not a run file: a run file is a regular HDF5 file "
            f"(it was not opened)"
        )


_TRUNCATED = re.compile(r"truncated file: eof = (\d+).*stored_eof = (\d+)")


def open_hdf5(path: str | Path) -> tuple[h5py.File, bool]:
    """Open plain read-only; a file still marked open for writing (a live SWMR writer, or
    one that was killed) is opened in SWMR-read mode instead. Returns (file, swmr).
    Raises ``UnreadableRunFile`` naming why the path cannot be opened as HDF5."""
    path = Path(path)
    check_regular_file(path)
    try:
        return h5py.File(path, "r"), False
    except OSError as exc:
        text = str(exc)
        m = _TRUNCATED.search(text)
        if m:
            raise UnreadableRunFile(
                f"{path} is truncated: {m.group(1)} bytes on disk, its HDF5 superblock records {m.group(2)} (cut "
                f"short by a copy or a download, or its writer failed while extending it, e.g. on a full disk; "
                f"`fbs recover {path}` repairs the latter where the metadata reads, or says "
                f"why it cannot)"
            ) from exc
        if "signature not found" in text:
            raise UnreadableRunFile(
                f"{path} is not an HDF5 file (no HDF5 signature in its "
                f"{_size(path)} bytes): a run file is an HDF5 file"
            ) from exc
        if "already open for write" not in text and "unable to lock" not in text.lower():
            raise UnreadableRunFile(f"cannot open {path} as HDF5: {exc}") from exc
    except (RuntimeError, ValueError, KeyError) as exc:
        raise UnreadableRunFile(f"cannot open {path} as HDF5: {exc}") from exc
    try:
        return open_swmr_read(path), True
    except (OSError, RuntimeError, ValueError, KeyError) as exc:
        if "not already open for SWMR writing" in str(exc):
            # marked open for writing, unlocked, never switched to SWMR: daq.runfile's writer
            # died between creating the file and its first flush (its metadata is on disk)
            raise UnreadableRunFile(
                f"{path} was left open for writing before its first flush (by a writer that died, "
                f"or one on another host): `fbs recover {path}` makes it readable when no writer "
                f"has it, or says why it cannot"
            ) from exc
        raise UnreadableRunFile(
            f"cannot open {path} (held by a writer, or left by one that died): {exc}"
        ) from exc


def _size(path: Path) -> int | str:
    try:
        return path.stat().st_size
    except OSError:
        return "?"


class RunFile:
    """An open run file. Use as a context manager."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.f, self.swmr = open_hdf5(self.path)
        try:
            self._check()
        except BaseException:
            self.f.close()
            raise

    def _check(self) -> None:
        """The layout contract (module docstring), from metadata only. Sets ``_group``,
        ``channels``, ``rate_hz`` and ``units``; raises ``ContractError`` naming every rule
        broken, ``UnreadableRunFile`` if HDF5 cannot read the metadata."""
        try:
            live = self.swmr or as_text(self.f.attrs.get("status", "")) == STATUS_RECORDING
            problems, found = contract_problems(self.f, live=live)
        except RunFileError:
            raise
        except (OSError, RuntimeError, KeyError, ValueError, TypeError, AttributeError) as exc:
            raise UnreadableRunFile(
                f"{self.path}: its HDF5 metadata cannot be read ({type(exc).__name__}: {exc})"
            ) from exc
        if problems:
            raise contract_error(self.path, problems)
        self._group = self.f["channels"]
        self.channels: tuple[str, ...] = found.channels
        self.rate_hz = found.rate_hz
        self.units = found.units

    # ------------------------------------------------------------------ description
    @property
    def attrs(self) -> dict[str, Any]:
        """The root attributes (strings decoded; one HDF5 cannot read shows why)."""
        out: dict[str, Any] = {}
        for k in self.f.attrs:
            try:
                v = self.f.attrs[k]
            except (OSError, RuntimeError, TypeError, ValueError) as exc:
                v = f"<unreadable: {exc}>"
            out[k] = as_text(v) if isinstance(v, (bytes, str)) else v
        return out

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
        s = as_text(self.f.attrs.get("status", ""))
        if s == STATUS_RECORDING and self.writer_alive() is False:
            return "aborted: the writer died without closing the file (run `fbs recover` on it)"
        return s

    def writer_alive(self) -> bool | None:
        """Whether the process that wrote the file still runs (None: cannot tell)."""
        return writer_alive(as_text(self.f.attrs.get("writer", "")))

    @property
    def events(self) -> list[Event]:
        if "events" not in self.f:
            return []
        ds = self.f["events"]
        problem = events_problem(ds)
        if problem:
            raise ContractError(f"{self.path}: {problem}", [problem])
        try:
            rows = ds[()]
            return [Event(float(r["time"]), as_text(r["kind"]), as_text(r["text"])) for r in rows]
        except (OSError, RuntimeError, TypeError, ValueError) as exc:
            raise UnreadableRunFile(f"{self.path}: /events cannot be read ({exc})") from exc

    @property
    def meta(self) -> dict[str, Any]:
        if "meta" not in self.f:
            return {}
        out = {}
        for k, v in self.f["meta"].attrs.items():
            try:
                out[k] = json.loads(as_text(v))
            except (TypeError, ValueError):
                out[k] = as_text(v)
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
            raise RunFileError(
                f"{self.path} lacks channel(s) {', '.join(missing)} "
                f"(has {', '.join(self.channels)})"
            )

    def read(
        self, channels: Sequence[str] | None = None, start: int = 0, stop: int | None = None
    ) -> np.ndarray:
        """Samples ``start .. stop`` of ``channels`` (default all) as (n_channels, n)."""
        channels = list(self.channels if channels is None else channels)
        self._need(channels)
        n = self.n_samples
        stop = n if stop is None else stop
        if not 0 <= start <= stop <= n:
            raise ValueError(f"samples {start}..{stop} are outside {self.path} (0..{n})")
        # NaN, not np.empty: HDF5 leaves the buffer alone where a chunk was never written
        # (fill_time "never", or a writer that died between extending and writing)
        try:
            out = np.full((len(channels), stop - start), np.nan)
        except MemoryError:
            raise RunFileError(
                f"{self.path}: samples {start}..{stop} of {len(channels)} channel(s) "
                f"({8 * len(channels) * (stop - start) / 1e9:.3g} GB) do not fit in memory; "
                f"analyse a shorter span"
            ) from None
        for i, c in enumerate(channels):
            if stop > start:
                try:
                    self._group[c].read_direct(out, np.s_[start:stop], np.s_[i, :])
                except (OSError, RuntimeError, TypeError, ValueError) as exc:
                    raise UnreadableRunFile(
                        f"{self.path}: samples {start}..{stop} of channel {c} cannot be "
                        f"read ({exc})"
                    ) from exc
        return out

    def lost_spans(
        self, channel: str, start: int = 0, stop: int | None = None, block_samples: int = 1 << 20
    ) -> list[tuple[int, int]]:
        """``(start, stop)`` of every run of lost (non-finite) samples of ``channel`` in samples
        ``start .. stop``, read a block at a time (bounded memory on a file of any size)."""
        spans: list[tuple[int, int]] = []
        for b in self.blocks(block_samples, channels=[channel], start=start, stop=stop):
            for a, e in nonfinite_spans(b.data[0]):
                if spans and spans[-1][1] == b.start + a:  # a run across the block boundary
                    spans[-1] = (spans[-1][0], b.start + e)
                else:
                    spans.append((b.start + a, b.start + e))
        return spans

    def slice_s(self, t0_s: float, t1_s: float, channels: Sequence[str] | None = None) -> Block:
        """The samples with t0_s <= t < t1_s (t = index / rate, from the start of the run)."""
        if not t1_s >= t0_s:
            raise ValueError(f"time slice {t0_s}..{t1_s} s is empty or reversed")
        n = self.n_samples
        a = min(n, max(0, int(np.ceil(t0_s * self.rate_hz - 1e-9))))
        b = min(n, max(a, int(np.ceil(t1_s * self.rate_hz - 1e-9))))
        channels = tuple(self.channels if channels is None else channels)
        return Block(a, self.rate_hz, channels, self.read(channels, a, b))

    def blocks(
        self,
        block_samples: int | None = None,
        *,
        block_s: float | None = None,
        channels: Sequence[str] | None = None,
        overlap: int = 0,
        start: int = 0,
        stop: int | None = None,
    ) -> Iterator[Block]:
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
            raise ValueError(
                f"block of {size} samples with overlap {overlap}: need size >= 1, 0 <= overlap < size"
            )
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


def read_channels(
    path: str | Path, names: list[str] | None = None
) -> tuple[dict[str, np.ndarray], float]:
    """Whole channels of a run file (in memory), and the common sample rate."""
    with RunFile(path) as run:
        names = list(run.channels) if names is None else names
        data = run.read(names)
        return dict(zip(names, data)), run.rate_hz
