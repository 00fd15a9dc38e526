"""The "fbs-run" HDF5 layout, version 1 (DESIGN.md section 6), and its streaming writer.

Root attributes ``format``, ``format_version``, ``created``, ``rig``, ``mode`` and optionally
``axis``, ``procedure``, ``status``; group ``/channels`` with one 1-D float dataset per
channel (attributes ``units``, ``sample_rate_hz``), all on one time base from t = 0; optional
``/events`` (time, kind, text) and ``/meta`` (JSON strings). Readable with plain h5py.

How the writer keeps data safe:

* The file is written in SWMR mode (HDF5 single-writer/multiple-reader), so the console and
  other processes read it while it grows (``h5py.File(path, "r", swmr=True)``), and a writer
  killed at any moment leaves a file whose metadata is consistent up to its last flush.
* Samples are buffered channel-major and written with the pending events when
  ``buffer_bytes`` fill, and at least every ``flush_s`` seconds of wall time (0.5 s by
  default), when the write also ends in ``H5Fflush``. A killed writer loses at most what
  was not yet flushed: ``flushed`` counts the samples readers are sure to see.
* The writing is done by one thread of the writer's own, from the second of two buffers,
  while the caller fills the first: a slow disk delays the acquisition only when a whole
  buffer is waiting. An error there (disk full) is raised by the caller's next call.
* Event strings are fixed-length (variable-length strings live in the global heap, which a
  killed SWMR writer can leave unreadable): ``kind`` up to 32 bytes, ``text`` up to 1024
  bytes of UTF-8; a longer text is cut at a character boundary and ends in "[cut]".
* ``status`` is "recording" while the writer has the file; ``close`` sets "complete" or
  "aborted: <why>". A file still saying "recording" whose writer is gone was not closed:
  ``fbs recover`` (``daq.recover``) makes it open with plain ``h5py.File(path)`` again.
* The file never exists under its name without its metadata on disk: it is created under a
  hidden name in the same folder (``.NAME.creating-HOST-PID-N``), laid out, flushed, given the
  room to be closed in, and only then linked to its name (``os.link``: atomic, and it never
  replaces a file that appeared meanwhile). A writer killed after that leaves a file that
  ``fbs recover`` turns into an "aborted" one with its metadata and no samples; one killed
  before leaves only the hidden file, removed by the next writer of that name on this host.
  A ``set_meta`` after creation reaches the disk with the first flush.
* An existing file is never overwritten unless asked (``overwrite=True``: ``os.replace``).
* Chunked datasets go straight to disk (no chunk cache, and ``fill_time="never"``: with
  HDF5's default fill time every new chunk would be filled and staged through a temporary
  chunk buffer first, one extra copy of all the data). Whole chunks are written with
  ``H5Dwrite_chunk``, a partial chunk at either end of a write with ``H5Dwrite`` where it
  belongs. Every sample inside a channel's extent is written by the write that extends it.
* Disk space is reserved ahead of the writes (``daq.prealloc``: ``fallocate`` keeping the
  file's size, about 30 % cheaper writes on ext4) and what is left over is returned at close.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import errno
import importlib.metadata
import itertools
import json
import logging
import math
import os
import shutil
import socket
import time
from collections.abc import Callable, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np
from h5py import h5a, h5d, h5p, h5s, h5t

from daq.prealloc import DiskFull, Preallocator, release

log = logging.getLogger(__name__)

try:  # the installed distribution's version, for the file's provenance
    __version__ = importlib.metadata.version("fbs-hil")
except importlib.metadata.PackageNotFoundError:  # run from a checkout that was never installed
    __version__ = "unknown"

FORMAT = "fbs-run"
FORMAT_VERSION = 1
#: HDF5 format bounds (DESIGN.md section 6): every object encoded as HDF5 1.10 reads it, and
#: SWMR (which needs 1.10's superblock) still works. "latest" let the installed library (2.x)
#: choose newer encodings that 1.10 tools (h5dump 1.10.8) could not read.
LIBVER = ("v110", "v110")
STATUS_RECORDING = "recording"
STATUS_COMPLETE = "complete"
KIND_BYTES = 32
TEXT_BYTES = 1024
EVENT_DTYPE = np.dtype(
    [
        ("time", "f8"),
        ("kind", h5py.string_dtype("utf-8", KIND_BYTES)),
        ("text", h5py.string_dtype("utf-8", TEXT_BYTES)),
    ]
)
_CUT = " [cut]"
_F8 = h5t.py_create(np.dtype("<f8"))  # the channels' type, for h5py's low-level calls
_VSTR = h5py.string_dtype()  # str attributes as attrs[...] = "..." stores them
#: Rows transposed into the channel-major buffer at a time: a tile (128 KiB at 16 channels)
#: stays in cache while it is scattered, ~25 % faster than one big strided copy.
_TILE = 1024
#: Disk kept reserved past every write for closing the file after the disk filled: the last
#: metadata flush and the status attribute (measured: under 20 KiB for 16 channels).
CLOSE_HEADROOM_BYTES = 256 << 10
#: Room asked for past a write's samples: the chunk index, the events, the object headers.
_METADATA_MARGIN = 1 << 16


class RunFileError(OSError):
    """The run file cannot be created, written or read; the message says which file and why."""


def fit_utf8(text: str, limit: int) -> bytes:
    """``text`` as UTF-8 in at most ``limit`` bytes; cut at a character boundary, marked."""
    raw = text.encode("utf-8")
    if len(raw) <= limit:
        return raw
    cut = raw[: limit - len(_CUT)].decode("utf-8", errors="ignore").encode("utf-8")
    return cut + _CUT.encode()


def abort_status(exc: BaseException) -> str:
    """The ``status`` a run ended by ``exc`` gets."""
    why = "interrupted" if isinstance(exc, KeyboardInterrupt) else f"{type(exc).__name__}: {exc}"
    return f"aborted: {why}"


def chunk_samples(rate_hz: float, flush_s: float) -> int:
    """Chunk length: about one flush's worth of samples, a power of two in [1024, 131072]
    (1 MiB of float64).

    Small enough that a slow run does not rewrite a large partial chunk at every flush,
    large enough that a fast one writes few chunks.
    """
    want = max(1.0, rate_hz * flush_s)
    return int(min(131072, max(1024, 2 ** int(np.ceil(np.log2(want))))))


def _write_hint(exc: BaseException) -> str:
    text = str(exc)
    if "errno = 28" in text or "No space left" in text:
        return "the disk is full"
    if "errno = 27" in text or "File too large" in text:
        return "the file size limit was reached"
    if "errno = 5" in text or "Input/output error" in text:
        return "the disk reported an I/O error (removed?)"
    return "disk full, removed, or read-only?"


def make_folder(path: str | Path, what: str = "output folder") -> Path:
    """Make the folder ``path`` (and its parents) if missing; ``RunFileError`` says which part of
    the path is in the way (a file where a folder must be) or what the system refused, rather
    than "[Errno 17] File exists" about a name the user never typed."""
    path = Path(path)
    if path.is_dir():
        return path
    for part in (path, *path.parents):
        if part.exists() and not part.is_dir():
            where = "it" if part == path else f"{part}, on its path,"
            raise RunFileError(
                f"cannot make {what} {path}: {where} is a file, not a folder; choose another --out"
            )
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RunFileError(f"cannot make {what} {path}: {exc.strerror or exc}") from exc
    return path


def check_new_path(path: str | Path, overwrite: bool = False) -> None:
    """Raise ``RunFileError`` unless a run file can be created at ``path`` (its folder is
    made if missing). Call it before moving the rig, so a bad ``--out`` fails first."""
    if isinstance(path, str) and path.endswith(("/", os.sep)):
        raise RunFileError(
            f"cannot create run file {path!r}: it names a folder (it ends with '/'); give a file "
            f"name in it, e.g. {path}run.h5"
        )
    path = Path(path)
    if path.is_dir():
        raise RunFileError(f"cannot create run file {path}: it is a directory")
    if path.exists() and not overwrite:
        raise RunFileError(
            f"{path} exists; a recording is never overwritten: choose another file name or remove it"
        )
    make_folder(path.parent, "the run file's folder")
    if not os.access(path.parent, os.W_OK):
        raise RunFileError(f"cannot create run file {path}: folder {path.parent} is not writable")


def check_request(
    out: str | Path,
    *,
    duration_s: float,
    rate_hz: float,
    n_channels: int,
    max_rate_hz: float,
    overwrite: bool = False,
) -> None:
    """Refuse, before anything is opened or a rig is told anything, a recording that cannot be
    what was meant: a duration or rate that is not a finite positive number, a rate beyond
    ``max_rate_hz``, fewer than two samples, more data than the output's disk has room for, or
    an output that exists (unless ``overwrite``; even then never one a writer may still be
    filling). ``ValueError`` or ``RunFileError`` names the value and the limit."""
    for name, v in (("duration", duration_s), ("rate", rate_hz)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"--{name} {v!r} must be a finite number > 0")
    if rate_hz > max_rate_hz:
        raise ValueError(
            f"--rate {rate_hz:g} Hz is beyond the {max_rate_hz:g} Hz this command can deliver"
        )
    samples = duration_s * rate_hz
    if samples < 2:
        raise ValueError(
            f"--duration {duration_s:g} s at --rate {rate_hz:g} Hz gives {samples:.3g} samples; "
            f"at least 2 are needed"
        )
    check_new_path(out, overwrite)
    out = Path(out)
    if out.exists():
        try:
            with h5py.File(out, "r") as f:
                status = str(f.attrs.get("status", ""))
        except OSError as exc:
            raise RunFileError(
                f"{out} cannot be opened ({exc}): perhaps a writer has it; not replaced"
            ) from None
        if status == STATUS_RECORDING:
            raise RunFileError(
                f"{out} has status {STATUS_RECORDING!r} (a writer may still be filling it): "
                f"not replaced, even with --force"
            )
    # float64 per channel, a little for the layout, and the room the writer keeps to close in
    need = samples * n_channels * 8 * 1.05 + CLOSE_HEADROOM_BYTES + _METADATA_MARGIN
    free = shutil.disk_usage(out.parent).free
    if need > free:
        raise ValueError(
            f"--duration {duration_s:g} s at --rate {rate_hz:g} Hz needs about {need / 1e9:.3g} GB; "
            f"{out.parent} has {free / 1e9:.3g} GB free"
        )


class RunWriter:
    """Streaming writer of one run file. Use as a context manager, from one thread.

    ``channels`` maps each channel name to its units, in the order of the columns that
    ``append`` takes. Until the first flush (``flush_s`` after creation, a full buffer, or
    ``flush``) the file is not yet in SWMR mode and ``set_meta`` may still add to it.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        rig: str,
        mode: int,
        rate_hz: float,
        channels: Mapping[str, str],
        axis: str | None = None,
        procedure: str | None = None,
        meta: Mapping[str, Any] | None = None,
        overwrite: bool = False,
        flush_s: float = 0.5,
        buffer_bytes: int = 16 << 20,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not (np.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"sample rate {rate_hz!r} Hz must be a positive number")
        if not channels:
            raise ValueError("a run file needs at least one channel")
        bad = [c for c in channels if not c or "/" in c or c in (".", "..")]
        if bad:
            raise ValueError(
                f"channel name(s) {bad} cannot name an HDF5 dataset (empty, '/', '.' or '..')"
            )
        if not flush_s > 0:
            raise ValueError(f"flush interval {flush_s!r} s must be > 0")
        self.path = Path(path)
        self.rate_hz = float(rate_hz)
        self.names = tuple(channels)
        self.flush_s = float(flush_s)
        self._clock = clock
        self._swmr = False
        n_ch = len(self.names)
        self._chunk = chunk_samples(self.rate_hz, self.flush_s)
        cap = max(1, int(buffer_bytes) // (8 * n_ch))
        self._cap = cap // self._chunk * self._chunk or cap  # whole chunks when it can hold one
        # two channel-major buffers (each channel's run contiguous): the acquisition fills one
        # while the write thread writes the other
        self._buf = np.empty((n_ch, self._cap))
        self._spare = np.empty((n_ch, self._cap))
        self._pool = ThreadPoolExecutor(
            max_workers=1, thread_name_prefix=f"runfile-{self.path.name}"
        )
        self._inflight: Future | None = None
        self._k = 0  # samples in self._buf
        self._submitted = 0  # samples handed to the write thread
        self.written = 0  # samples written to the file
        self.flushed = 0  # samples flushed (visible to SWMR readers)
        self._events: list[tuple[float, bytes, bytes]] = []
        self._n_events = 0
        self._failed: str | None = None
        self._closed = False
        self._last_flush = clock()
        self._tmp: Path | None = None  # the file's name until it is published
        self._open(overwrite)
        try:
            self._layout(rig, mode, channels, axis, procedure, meta or {})
            self.f.flush()  # the whole layout on disk before it has a name
            # disk reserved ahead: about 2 s of data, at least 1 MiB, at most two buffers. The
            # room to close the file in is reserved now, so a disk that fills before the first
            # write still lets the file be closed with its status; after the flush, whose
            # truncate to HDF5's end of file would return it
            row = 8 * n_ch
            step = min(2 * self._cap * row, max(1 << 20, int(2 * self.rate_hz) * row))
            self._space = Preallocator(self.f.id.get_vfd_handle(), step, CLOSE_HEADROOM_BYTES)
            self._space.reserve(0)
        except BaseException as exc:  # Ctrl-C too: nothing is left behind
            self._discard()
            if isinstance(exc, DiskFull):
                raise RunFileError(
                    f"cannot create run file {self.path}: the disk is full "
                    f"({exc.strerror}); nothing was created. Free some space or "
                    f"record to another disk"
                ) from exc
            if isinstance(exc, (OSError, ValueError, RuntimeError, TypeError)):
                raise RunFileError(
                    f"cannot lay out run file {self.path} ({_write_hint(exc)}): {exc}"
                ) from exc
            raise
        try:
            self._publish(overwrite)
        except BaseException:
            self._discard()
            raise

    # ------------------------------------------------------------------ creation
    def _open(self, overwrite: bool) -> None:
        """Create the file under its hidden temporary name (``_publish`` gives it its own)."""
        check_new_path(self.path, overwrite)
        _remove_dead_temps(self.path)
        tmp = _temp_name(self.path)
        # a file of this name is a dead writer's whose pid this process now has; once it is
        # gone, whatever is there after a failed creation was made by it (a full disk)
        try:
            tmp.unlink(missing_ok=True)
            self.f = h5py.File(tmp, "w-", libver=LIBVER, rdcc_nbytes=0)
        except (OSError, ValueError) as exc:
            with contextlib.suppress(OSError):
                tmp.unlink(missing_ok=True)
            hint = _write_hint(exc)
            why = "" if hint.endswith("?") else f" ({hint}; nothing was created)"
            raise RunFileError(f"cannot create run file {self.path}{why}: {exc}") from exc
        self._tmp = tmp

    def _publish(self, overwrite: bool) -> None:
        """Give the laid-out file its name: a hard link, which fails rather than replace a file
        made there since ``check_new_path`` (``os.replace`` where replacing was asked for)."""
        tmp = self._tmp
        assert tmp is not None
        try:
            if overwrite:
                os.replace(tmp, self.path)
            else:
                try:
                    os.link(tmp, self.path)
                except FileExistsError:
                    raise
                except OSError as exc:
                    # a filesystem without hard links (FAT, some network ones): a rename after
                    # a look, which leaves a moment in which another file could be replaced
                    if exc.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.ENOSYS, errno.EMLINK):
                        raise
                    if os.path.lexists(self.path):
                        raise FileExistsError(errno.EEXIST, "File exists") from None
                    os.rename(tmp, self.path)
                else:  # published; a second name left here is removed as a dead writer's
                    with contextlib.suppress(OSError):
                        tmp.unlink()
        except FileExistsError:
            raise RunFileError(
                f"{self.path} exists (it appeared while this recording was being "
                f"created); a recording is never overwritten: choose another file "
                f"name"
            ) from None
        except OSError as exc:
            raise RunFileError(f"cannot create run file {self.path}: {exc}") from exc
        self._tmp = None

    def _discard(self) -> None:
        """Close and remove the file not yet published: ours, and holding nothing yet."""
        try:
            self.f.close()
        except (OSError, RuntimeError) as exc:
            log.debug("closing the unpublished %s: %s", self._tmp, exc)
        if self._tmp is not None:
            with contextlib.suppress(OSError):
                self._tmp.unlink(missing_ok=True)

    def _layout(
        self,
        rig: str,
        mode: int,
        channels: Mapping[str, str],
        axis: str | None,
        procedure: str | None,
        meta: Mapping[str, Any],
    ) -> None:
        a = self.f.attrs
        a["format"] = FORMAT
        a["format_version"] = FORMAT_VERSION
        a["created"] = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
        a["rig"] = rig
        a["mode"] = int(mode)
        a["status"] = STATUS_RECORDING
        a["writer"] = f"fbs-hil {__version__}, pid {os.getpid()} on {socket.gethostname()}"
        if axis is not None:
            a["axis"] = axis
        if procedure is not None:
            a["procedure"] = procedure
        g = self.f.create_group("channels")
        chunk = self._chunk
        # h5py's low-level calls: half the time of create_dataset and attrs[...] (~6 ms for 16 channels)
        dcpl = h5p.create(h5p.DATASET_CREATE)
        dcpl.set_chunk((chunk,))
        dcpl.set_fill_time(h5d.FILL_TIME_NEVER)
        # no modification-time message, as h5py's create_dataset: the object header is not
        # rewritten with a new time at every extension (5-7 % of a loop of extend + chunk write;
        # no measurable change in the streaming bench, whose limit is elsewhere: docs/runfile.md)
        dcpl.set_obj_track_times(False)
        space = h5s.create_simple((0,), (h5s.UNLIMITED,))
        rate = np.array(self.rate_hz)
        str_type, rate_type = (h5t.py_create(_VSTR, logical=True), h5t.py_create(rate.dtype))
        scalar = h5s.create(h5s.SCALAR)
        self.datasets = []
        for name, units in channels.items():
            did = h5d.create(g.id, name.encode(), _F8, space, dcpl=dcpl)
            h5a.create(did, b"units", str_type, scalar).write(np.array(units, dtype=_VSTR))
            h5a.create(did, b"sample_rate_hz", rate_type, scalar).write(rate)
            self.datasets.append(h5py.Dataset(did))
        self.events = self.f.create_dataset(
            "events", shape=(0,), maxshape=(None,), dtype=EVENT_DTYPE, chunks=(64,)
        )
        self.meta = self.f.create_group("meta")
        self.meta.attrs["software_version"] = json.dumps({"fbs-hil": __version__})
        for k, v in meta.items():
            self.meta.attrs[k] = json.dumps(v, default=str)

    def set_meta(self, name: str, value: Any) -> None:
        """Store ``value`` as JSON in ``/meta`` (before the first flush, which writes it)."""
        if self._swmr:
            raise RuntimeError(
                f"{self.path}: a meta can only be added before the first sample or event "
                "(SWMR files cannot grow new objects)"
            )
        self.meta.attrs[name] = json.dumps(value, default=str)

    # ------------------------------------------------------------------ streaming
    @property
    def samples(self) -> int:
        """Samples appended so far (on disk, being written, or buffered)."""
        return self._submitted + self._k

    def append(self, block: np.ndarray | Mapping[str, np.ndarray]) -> None:
        """Append samples: an (n, n_channels) array in channel order, or every channel by name."""
        if isinstance(block, Mapping):
            if set(block) != set(self.names):
                raise ValueError(
                    f"a block must hold exactly the channels {self.names}, got {tuple(block)}"
                )
            lengths = {len(block[c]) for c in self.names}
            if len(lengths) != 1:
                raise ValueError(f"channel blocks of different lengths {sorted(lengths)}")
            cols = np.stack([np.asarray(block[c], dtype=float) for c in self.names])
        else:
            a = np.asarray(block, dtype=float)
            if a.ndim != 2 or a.shape[1] != len(self.names):
                raise ValueError(f"a block must be (n, {len(self.names)}), got shape {a.shape}")
            cols = a.T
        self._put(cols)

    def append_missing(self, n: int) -> None:
        """``n`` lost samples on every channel: written as NaN, never spliced over."""
        if n < 0:
            raise ValueError(f"cannot append {n} samples")
        while n:
            m = min(n, self._cap)
            self._put(None, m)
            n -= m

    def _put(self, cols: np.ndarray | None, n: int | None = None) -> None:
        self._check_ok()
        if cols is not None:
            n = cols.shape[1]
        assert n is not None  # without columns, the caller (append_missing) gives the count
        pos = 0
        while pos < n:
            m = min(n - pos, self._room() - self._k)
            if cols is None:
                self._buf[:, self._k : self._k + m].fill(np.nan)
            elif cols.strides[1] == cols.itemsize:  # channel-major already (ADC blocks are)
                self._buf[:, self._k : self._k + m] = cols[:, pos : pos + m]
            else:
                for j in range(0, m, _TILE):
                    e = min(m, j + _TILE)
                    self._buf[:, self._k + j : self._k + e] = cols[:, pos + j : pos + e]
            self._k += m
            pos += m
            if self._k == self._room():
                self._hand_off(flush=False)
        if self._clock() - self._last_flush >= self.flush_s:
            self._hand_off()

    def _room(self) -> int:
        """Samples the current buffer takes before it is handed off: up to the next multiple of
        its size, so that the buffers after a flush end on whole chunks again."""
        return self._cap - self._submitted % self._cap

    def event(self, time_s: float, kind: str, text: str) -> None:
        """Add an event; it reaches the file with the next flush."""
        self._check_ok()
        self._events.append((float(time_s), fit_utf8(kind, KIND_BYTES), fit_utf8(text, TEXT_BYTES)))
        if self._clock() - self._last_flush >= self.flush_s:
            self._hand_off()

    def flush(self) -> None:
        """Write the buffered samples and events and flush the file; returns when they are
        on disk (readers see them: ``flushed``)."""
        self._hand_off()
        self.sync()

    def sync(self) -> None:
        """Wait for the write in flight, if any; raise ``RunFileError`` if it failed."""
        if self._inflight is not None:
            self._inflight.result()
            self._inflight = None
        self._check_ok()

    def _hand_off(self, flush: bool = True) -> None:
        """Give the buffer and the pending events to the write thread and go on with the other
        buffer; ``flush``: the write ends in H5Fflush (due by time, or asked for). A buffer
        that fills sooner is written without one: readers may not see it until the next flush,
        at most ``flush_s`` later. Waits only if the previous write has not finished."""
        self.sync()
        self._swmr = True  # from here on the file is (being switched to) SWMR
        job = (self._buf, self._k, self._submitted, self._events, flush)
        self._submitted += self._k
        self._buf, self._spare = self._spare, self._buf
        self._k = 0
        self._events = []
        if flush:
            self._last_flush = self._clock()
        self._inflight = self._pool.submit(self._write, *job)

    def _write(self, buf: np.ndarray, k: int, n0: int, events: list, flush: bool) -> None:
        """On the write thread: append ``k`` samples at ``n0`` and the events; H5Fflush if
        ``flush``."""
        try:
            if not self.f.swmr_mode:
                # written in the room reserved at creation. The switch can shrink the file (the
                # layout flush left HDF5's spare metadata block at its end), which returns the
                # blocks reserved past it: the room to close in is taken back first
                self.f.swmr_mode = True
                self._space.truncated()
                self._space.reserve(0)
            # every byte this write can need is the file's before HDF5 writes one: HDF5 cannot
            # survive a disk found full half-way through its metadata (daq.prealloc)
            self._space.reserve(
                k * buf.shape[0] * buf.itemsize
                + _METADATA_MARGIN
                + len(events) * EVENT_DTYPE.itemsize
            )
        except DiskFull as exc:
            self._failed = (
                f"writing {self.path} stopped: the disk is full ({exc.strerror}). Nothing of samples "
                f"{n0}..{n0 + k} was written. Samples 0..{self.flushed} ({self.flushed / self.rate_hz:.3f} s)"
                f" were flushed before and are kept. Free some space or record to another disk"
            )
            raise RunFileError(self._failed) from exc
        except (OSError, ValueError, RuntimeError) as exc:
            done = f"0..{self.flushed} ({self.flushed / self.rate_hz:.3f} s)"
            self._failed = (
                f"writing {self.path} failed ({_write_hint(exc)}): {exc}. Samples "
                f"{done} were flushed before"
            )
            raise RunFileError(self._failed) from exc
        try:
            if k:
                for i, ds in enumerate(self.datasets):
                    self._write_channel(ds.id, buf[i, :k], n0)
            if events:
                new = np.array(events, dtype=EVENT_DTYPE)
                self.events.resize((self._n_events + len(new),))
                self.events[self._n_events :] = new
            if flush:
                self.f.flush()
        except (OSError, ValueError, RuntimeError) as exc:
            self._failed = (
                f"writing {self.path} failed ({_write_hint(exc)}): {exc}. Samples 0..{self.flushed} "
                f"({self.flushed / self.rate_hz:.3f} s) were flushed before"
            )
            self._roll_back(n0)
            raise RunFileError(self._failed) from exc
        self._n_events += len(events)
        self.written = n0 + k
        if flush:
            self.flushed = self.written

    def _roll_back(self, n0: int) -> None:
        """After a failed write: no channel keeps an extent past ``n0``, where samples that never
        reached the disk would read as zeros. Best effort: the disk may refuse this too."""
        for ds in self.datasets:
            try:
                if ds.id.shape[0] > n0:
                    ds.id.set_extent((n0,))
            except (OSError, ValueError, RuntimeError) as exc:
                log.warning(
                    "%s: could not take channel %s back to %d samples: %s",
                    self.path,
                    ds.name,
                    n0,
                    exc,
                )

    def _write_channel(self, did: h5d.DatasetID, x: np.ndarray, n0: int) -> None:
        """Extend one channel's dataset by ``x`` at ``n0``. Whole chunks go straight to the file
        (``H5Dwrite_chunk``: no selection, no chunk lookup); a partial chunk at either end is
        written through ``H5Dwrite`` where it belongs. h5py's low-level calls: the high-level
        resize/write_direct rebuild selections on every call (~25 ms per 256 MB here)."""
        k, c = len(x), self._chunk
        did.set_extent((n0 + k,))
        head = min(k, -n0 % c)  # up to the first chunk boundary
        whole = (k - head) // c * c
        for a, b in ((0, head), (head + whole, k)):
            if b > a:
                mem = h5s.create_simple((b - a,))
                space = did.get_space()
                space.select_hyperslab((n0 + a,), (b - a,))
                did.write(mem, space, x[a:b])
        for a in range(head, head + whole, c):
            did.write_direct_chunk((n0 + a,), x[a : a + c])

    @property
    def failed(self) -> str | None:
        """Why writing failed, if it did (the writer then refuses more data)."""
        return self._failed

    @property
    def is_open(self) -> bool:
        return not self._closed

    def _check_ok(self) -> None:
        if self._failed:
            raise RunFileError(self._failed)
        if self._closed:  # not f.id.valid: h5py's lock would wait for the write thread's write
            raise RunFileError(f"{self.path} is closed")

    # ------------------------------------------------------------------ closing
    def close(self, status: str = STATUS_COMPLETE) -> None:
        """Flush, close, and set the root ``status``. Idempotent.

        SWMR files cannot take attribute changes, so the file is closed and reopened for the
        status. If the last flush fails the status says so and the error is raised; samples
        flushed before stay in the file.
        """
        if self._closed:
            return
        error: RunFileError | None = None
        if not self._failed:
            try:
                self.flush()
            except RunFileError as exc:
                error = exc
        self._closed = True
        if self._inflight is not None:  # a failed write still has to end first
            try:
                self._inflight.result()
            except RunFileError:
                pass
        self._pool.shutdown(wait=True)
        if self._failed and not status.startswith("aborted"):
            status = f"aborted: {self._failed}"
            error = error or RunFileError(self._failed)  # even if no earlier call raised it
        try:
            self.f.close()
        except (
            OSError,
            RuntimeError,
        ) as exc:  # h5py raises either; the status attempt still follows
            log.error("closing %s failed: %s", self.path, exc)
        try:
            _set_status(self.path, status)
        except (OSError, RuntimeError) as exc:
            # the file still says "recording"; recover marks such a file aborted, where it can
            log.error(
                "could not set the status of %s to %r: %s. It still says %r; "
                "`fbs recover %s` marks it aborted, keeping its flushed samples, once "
                "its disk has room, or says why it cannot",
                self.path,
                status,
                exc,
                STATUS_RECORDING,
                self.path,
            )
        try:
            release(self.path)
        except OSError as exc:
            log.warning(
                "could not return the disk space reserved past the end of %s: %s", self.path, exc
            )
        if error is not None:
            raise error

    def __enter__(self) -> RunWriter:
        return self

    def __exit__(self, et: type | None, ev: BaseException | None, tb: TracebackType | None) -> None:
        self.close(STATUS_COMPLETE if ev is None else abort_status(ev))


_TEMP_MARK = ".creating-"
_temp_serial = itertools.count()  # two writers of one process never share a temporary name


def _temp_prefix(path: Path) -> str:
    """``.NAME.creating-HOST-``: the temporary names of ``path`` made on this host. NAME is cut
    to 100 bytes, leaving room for the rest within a file name's 255."""
    stem = os.fsencode(path.name)[:100].decode("utf-8", "ignore")
    return f".{stem}{_TEMP_MARK}{socket.gethostname()}-"


def _temp_name(path: Path) -> Path:
    """The hidden name ``path`` is created under: in its folder (a link cannot leave the
    filesystem), saying whose it is, so that a dead writer's leftover can be told."""
    return path.with_name(f"{_temp_prefix(path)}{os.getpid()}-{next(_temp_serial)}")


def _remove_dead_temps(path: Path) -> None:
    """Remove temporary files for ``path`` whose writer (on this host) is gone: a writer
    killed while it created the file leaves one. Best effort: one look at the folder."""
    prefix = _temp_prefix(path)
    try:
        names = [n for n in os.listdir(path.parent) if n.startswith(prefix)]
    except OSError:
        return
    for name in names:
        pid, _, serial = name[len(prefix) :].partition("-")
        if not (pid.isdigit() and serial.isdigit()) or int(pid) == os.getpid():
            continue
        try:
            os.kill(int(pid), 0)
            continue  # alive (or another process got the number): not ours to judge
        except ProcessLookupError:
            pass
        except OSError:
            continue
        try:
            os.unlink(path.parent / name)
            log.info("removed %s, left by a writer that died creating %s", path.parent / name, path)
        except OSError as exc:
            log.debug("could not remove %s: %s", path.parent / name, exc)


def _set_status(path: Path, status: str) -> None:
    """Set the root status of a closed run file. A live SWMR reader (the console) holds a
    read lock on it; the one attribute is then written without taking the lock."""
    set_root_attr(path, "status", status)


def set_root_attr(path: str | Path, name: str, value: str) -> None:
    """Set one root attribute of a closed run file (what became known after it closed: whether
    the rig's safe state was read back at the end)."""
    try:
        f = h5py.File(path, "r+")
    except OSError as exc:
        if "lock" not in str(exc).lower():
            raise
        f = h5py.File(path, "r+", locking=False)
    with f:
        f.attrs[name] = value
