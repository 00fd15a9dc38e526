"""Recover a run file whose writer died (SIGKILL, power cut, full disk) before closing it.

An SWMR writer marks the HDF5 superblock "open for writing" and leaves the end-of-file
address stale until it closes. A killed writer's file therefore opens only in SWMR-read
mode; plain ``h5py.File(path)`` refuses it ("file is already open for write (may use
<h5clear file> ...)"). A writer killed before its first flush (``daq.runfile``: the layout
flushed, not yet SWMR) leaves the flags too, and a file that opens in no mode at all; it is
repaired the same way, to its metadata and no samples. ``recover`` does what ``h5clear -s
--increment`` does, in place:

1. find the superblock (version 2 or 3, 8-byte addresses), check its checksum;
2. clear the file-consistency flags, set the end-of-file address to the file's size and
   write the new checksum (Jenkins' lookup3, as HDF5 computes it);
3. reopen with plain h5py: channels of unequal length (the writer died between two of
   them) are padded with NaN to the longest, with a ``gap`` event, so no sample is
   dropped; the status becomes "aborted: ..." with the number of samples kept.

Before any of that writes a byte, the file is surveyed read-only through a view that shows
it as step 2 would leave it (``_RepairedView``: the new superblock and the zero fill exist
only in memory): whether its metadata reads at all, how long its channels are, and so how
many bytes the repair will add. A repair that cannot succeed - metadata a failed write left
damaged, or a disk without room for the repair (recovering in place on the disk that filled
corrupted the file further) - is refused with nothing written: copy the file to a disk with
room and recover the copy.

It refuses a file whose writer is still running on this host.
"""

from __future__ import annotations

import io
import logging
import math
import os
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from daq.contract import member_dataset
from daq.prealloc import release
from daq.reader import as_text, writer_alive
from daq.runfile import (
    EVENT_DTYPE,
    KIND_BYTES,
    STATUS_RECORDING,
    TEXT_BYTES,
    RunFileError,
    fit_utf8,
)

log = logging.getLogger(__name__)

SIGNATURE = b"\x89HDF\r\n\x1a\n"
_M32 = 0xFFFFFFFF


def _rot(x: int, k: int) -> int:
    return ((x << k) | (x >> (32 - k))) & _M32


# lookup3's mix() and final() as (x, y, z, r) steps on v = [a, b, c]
_MIX = ((0, 2, 1, 4), (1, 0, 2, 6), (2, 1, 0, 8), (0, 2, 1, 16), (1, 0, 2, 19), (2, 1, 0, 4))
_FINAL = ((2, 1, 14), (0, 2, 11), (1, 0, 25), (2, 1, 16), (0, 2, 4), (1, 0, 14), (2, 1, 24))


def lookup3(data: bytes, initval: int = 0) -> int:
    """Bob Jenkins' lookup3 ``hashlittle``: HDF5's metadata checksum (H5_checksum_lookup3)."""
    n = len(data)
    v = [(0xDEADBEEF + n + initval) & _M32] * 3
    padded = data + bytes(-n % 12 if n else 0)
    words = [int.from_bytes(padded[i : i + 4], "little") for i in range(0, len(padded), 4)]
    blocks = [words[i : i + 3] for i in range(0, len(words), 3)]
    if not blocks:
        return v[2]
    for blk in blocks[:-1]:
        v = [(v[j] + blk[j]) & _M32 for j in range(3)]
        for x, y, z, r in _MIX:  # x -= y; x ^= rot(y, r); y += z
            v[x] = ((v[x] - v[y]) & _M32) ^ _rot(v[y], r)
            v[y] = (v[y] + v[z]) & _M32
    v = [(v[j] + blocks[-1][j]) & _M32 for j in range(3)]
    for x, y, r in _FINAL:  # x ^= y; x -= rot(y, r)
        v[x] = ((v[x] ^ v[y]) - _rot(v[y], r)) & _M32
    return v[2]


@dataclass(frozen=True)
class Superblock:
    offset: int  # where the signature is (0, 512, 1024, ...)
    version: int
    flags: int  # file-consistency flags: non-zero while a writer has the file
    base: int  # base address: file addresses count from here
    eof: int  # end-of-file address, relative to base

    def needs_repair(self, file_size: int) -> bool:
        """Marked open for writing, or shorter than its recorded end of file."""
        return self.flags != 0 or self.eof > file_size - self.base


def read_superblock(path: str | Path) -> Superblock:
    """The version 2/3 superblock of ``path``, its checksum verified."""
    path = Path(path)
    size = path.stat().st_size
    with open(path, "rb") as fh:
        offset = 0
        while offset < size:
            fh.seek(offset)
            raw = fh.read(48)
            if raw[:8] == SIGNATURE:
                if len(raw) < 48:
                    raise RunFileError(
                        f"{path}: cut short inside its HDF5 superblock ({len(raw)} of 48 bytes at "
                        f"offset {offset}); nothing is left to recover"
                    )
                break
            offset = 512 if offset == 0 else offset * 2
        else:
            raise RunFileError(f"{path}: no HDF5 signature found; not an HDF5 file")
    version = raw[8]
    if version not in (2, 3):
        raise RunFileError(
            f"{path}: superblock version {version} has no open-for-write flags to clear "
            "(only versions 2 and 3 do)"
        )
    if raw[9] != 8 or raw[10] != 8:
        raise RunFileError(
            f"{path}: {raw[9]}-byte offsets / {raw[10]}-byte lengths are not supported (8/8 only)"
        )
    stored = int.from_bytes(raw[44:48], "little")
    if lookup3(raw[:44]) != stored:
        raise RunFileError(
            f"{path}: superblock checksum mismatch; the file is damaged beyond this repair"
        )
    return Superblock(
        offset,
        version,
        raw[11],
        int.from_bytes(raw[12:20], "little"),
        int.from_bytes(raw[28:36], "little"),
    )


def _repaired_superblock(sb: Superblock, raw: bytes, size: int) -> bytes:
    """The 48 superblock bytes ``raw`` as the repair writes them: flags clear, the end-of-file
    address at least the file's size, the checksum recomputed."""
    new = bytearray(raw)
    new[11] = 0
    new[28:36] = max(sb.eof, size - sb.base).to_bytes(8, "little")
    new[44:48] = lookup3(bytes(new[:44])).to_bytes(4, "little")
    return bytes(new)


class _RepairedView(io.RawIOBase):
    """``path`` read-only, as ``clear_open_flags`` would leave it: the superblock repaired
    and the file zero-filled up to its recorded end - in memory only. HDF5 opens it through
    h5py's file-object driver."""

    def __init__(self, path: Path, sb: Superblock) -> None:
        super().__init__()
        self._fh = open(path, "rb")
        self._real = os.fstat(self._fh.fileno()).st_size
        self._fh.seek(sb.offset)
        self._patch = _repaired_superblock(sb, self._fh.read(48), self._real)
        self._at = sb.offset
        self.size = max(self._real, sb.base + sb.eof)
        self._pos = 0

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        self._pos = {io.SEEK_SET: 0, io.SEEK_CUR: self._pos, io.SEEK_END: self.size}[
            whence
        ] + offset
        return self._pos

    def tell(self) -> int:
        return self._pos

    def readinto(self, b: bytearray | memoryview) -> int:  # type: ignore[override]
        view = memoryview(b).cast("B")
        n = max(0, min(len(view), self.size - self._pos))
        real = max(0, min(n, self._real - self._pos))
        if real:
            self._fh.seek(self._pos)
            got = self._fh.readinto(view[:real]) or 0
            view[got:real] = bytes(real - got)
        view[real:n] = bytes(n - real)  # the zero fill past the real end
        lo, hi = max(self._pos, self._at), min(self._pos + n, self._at + len(self._patch))
        if lo < hi:
            view[lo - self._pos : hi - self._pos] = self._patch[lo - self._at : hi - self._at]
        self._pos += n
        return n

    def close(self) -> None:
        self._fh.close()
        super().close()


@dataclass(frozen=True)
class _Survey:
    """What the repair will find and add, read before it writes."""

    status: str
    writer: str  # the writer attribute ("fbs-hil V, pid P on HOST")
    rate_hz: float
    lengths: dict[str, int]
    events_ok: bool  # an events table the gap event can be added to

    @property
    def padding(self) -> dict[str, int]:
        n = max(self.lengths.values())
        return {c: n - m for c, m in self.lengths.items() if m < n}


#: Room a repair needs besides the zero fill and the padding: the object headers, the chunk
#: index and the status attribute HDF5 rewrites (a repaired 16-channel file grew < 20 KiB).
REPAIR_MARGIN_BYTES = 256 << 10


def _survey(path: Path, sb: Superblock | None) -> _Survey:
    """Read what the repair needs without writing: through ``_RepairedView`` when the
    superblock needs repair (``sb``), else the file itself, read-only."""
    src: Any = _RepairedView(path, sb) if sb is not None else path
    try:
        with h5py.File(src, "r") as f:
            status = as_text(f.attrs.get("status", ""))
            writer = as_text(f.attrs.get("writer", ""))
            for name in ("channels", "events"):  # never followed to another file (it may be a FIFO)
                if isinstance(f.get(name, getlink=True), h5py.ExternalLink):
                    raise RunFileError(
                        f"{path}: /{name} is a link to another file; not a run file this can repair"
                    )
            g = f.get("channels")
            if not isinstance(g, h5py.Group) or not len(g):
                raise RunFileError(
                    f"{path}: no /channels group with datasets; not a run file this can repair"
                )
            lengths: dict[str, int] = {}
            rate = math.nan
            for c in g:
                ds, why = member_dataset(g, c)
                if ds is None or ds.ndim != 1:
                    raise RunFileError(
                        f"{path}: /channels/{c} is {why or 'not 1-D'}; not a run file this can repair"
                    )
                lengths[c] = ds.shape[0]
                if not math.isfinite(rate):
                    rate = float(np.asarray(ds.attrs.get("sample_rate_hz", math.nan)).ravel()[0])
            if not (math.isfinite(rate) and rate > 0):
                raise RunFileError(
                    f"{path}: channel sample_rate_hz {rate!r} is not a positive number"
                )
            ev = f.get("events")
            events_ok = (
                isinstance(ev, h5py.Dataset) and ev.dtype == EVENT_DTYPE and ev.maxshape == (None,)
            )
            return _Survey(status, writer, rate, lengths, events_ok)
    except RunFileError:
        raise
    except (OSError, KeyError, ValueError, RuntimeError, TypeError, IndexError) as exc:
        raise RunFileError(
            f"{path}: its metadata cannot be read ({exc}); a write that failed (a full disk, a "
            f"crash) left it damaged beyond this repair. Nothing was written"
        ) from exc
    finally:
        if isinstance(src, _RepairedView):
            src.close()


def _refuse_without_room(path: Path, need: int) -> None:
    free = shutil.disk_usage(path.parent).free  # as ``runfile.check_request`` measures it
    if free < need:
        raise RunFileError(
            f"{path}: the repair needs about {need} bytes on its disk and {free} are free. Nothing "
            f"was written; copy the file to a disk with room and recover the copy"
        )


def clear_open_flags(path: str | Path) -> Superblock:
    """Clear the superblock's open-for-write flags and make its end-of-file address agree
    with the file (``h5clear -s --increment=0``). Returns the superblock as it was.

    A stale address below the file's size is raised to it. One above it (the writer's
    last extension failed: disk full) is met by zero-filling the file up to it; HDF5's
    metadata checksums then catch any structure that the failed write left incomplete.
    """
    path = Path(path)
    sb = read_superblock(path)
    size = path.stat().st_size
    with open(path, "r+b") as fh:
        fh.seek(sb.offset)
        raw = _repaired_superblock(sb, fh.read(48), size)
        if sb.eof > size - sb.base:
            fh.truncate(sb.base + sb.eof)
            log.warning(
                "%s: zero-filled %d bytes up to the recorded end of file",
                path,
                sb.base + sb.eof - size,
            )
        fh.seek(sb.offset)
        fh.write(raw)
        fh.flush()
        os.fsync(fh.fileno())
    return sb


@dataclass
class Recovery:
    path: Path
    was_open: bool  # the flags said open for writing
    samples: int  # samples per channel now in the file
    rate_hz: float
    padded: dict[str, int]  # channel -> NaN samples added to reach the longest
    status: str

    def summary(self) -> str:
        if not self.was_open:
            return f"{self.path}: was closed properly; status {self.status!r}; nothing to do"
        pad = (
            (", padded with NaN: " + ", ".join(f"{c} +{n}" for c, n in self.padded.items()))
            if self.padded
            else ""
        )
        return (
            f"{self.path}: recovered; {self.samples} samples per channel ({self.samples / self.rate_hz:.3f} s) "
            f"kept{pad}; status {self.status!r}; opens with plain h5py now"
        )


def _refuse_if_writer_alive(path: Path, writer: str, *, force: bool) -> None:
    """Refuse a file whose writer (its ``writer`` attribute) still runs. ``force`` overrides a
    writer that is only *said* to run (its pid alive on this host: perhaps another process got
    the number), never one that holds this very file open (``_holds_open``): that is the
    writer, and clearing its flags under it destroyed the file."""
    if not writer_alive(writer):
        return
    m = _WRITER_PID.search(writer)
    if m and _holds_open(int(m.group(1)), path):
        raise RunFileError(
            f"{path}: its writer ({writer}) is still running and has the file open; stop it "
            f"first (not even force repairs a file under its writer)"
        )
    if not force:
        raise RunFileError(
            f"{path}: its writer ({writer}) is still running; stop it first "
            "(or pass force if that process is not the writer)"
        )


_WRITER_PID = re.compile(r"pid (\d+) on ")


def _holds_open(pid: int, path: Path) -> bool:
    """Whether process ``pid`` has ``path`` open (Linux /proc; False where that cannot be seen).

    Compared by device and inode, not by the name /proc shows: a writer opens its file under a
    temporary name (``daq.runfile``), which /proc then shows as deleted."""
    try:
        target = path.stat()
        fds = list(Path(f"/proc/{pid}/fd").iterdir())
    except OSError:
        return False
    for fd in fds:
        try:
            st = fd.stat()  # follows the link to the open file, renamed or not
        except OSError:
            continue
        if (st.st_dev, st.st_ino) == (target.st_dev, target.st_ino):
            return True
    return False


def _held_by_anyone(path: Path) -> int | None:
    """The pid of a process on this host that has ``path`` open, if any (Linux /proc)."""
    for proc in Path("/proc").glob("[0-9]*"):
        if int(proc.name) != os.getpid() and _holds_open(int(proc.name), path):
            return int(proc.name)
    return None


def recover(path: str | Path, *, force: bool = False) -> Recovery:
    """Make a file left by a dead writer open with plain h5py, keeping every flushed sample.
    Raises ``RunFileError``, having written nothing, where the repair cannot succeed."""
    path = Path(path)
    if not path.is_file():
        raise RunFileError(
            f"{path}: {'no such file' if not path.exists() else 'not a regular file'}"
        )
    sb = read_superblock(path)
    size = path.stat().st_size
    was_open = sb.needs_repair(size)
    try:
        survey = _survey(path, sb if was_open else None)
    except RunFileError:
        pid = _held_by_anyone(path) if was_open else None
        if pid is not None:  # a live writer's metadata may be caught half-written: not damage
            raise RunFileError(
                f"{path}: process {pid} has the file open (its writer?); stop it first"
            ) from None
        raise
    if was_open and sb.flags:
        _refuse_if_writer_alive(path, survey.writer, force=force)
    padding = survey.padding
    if was_open or padding or survey.status == STATUS_RECORDING:
        fill = max(0, sb.base + sb.eof - size) if was_open else 0
        _refuse_without_room(path, fill + 8 * sum(padding.values()) + REPAIR_MARGIN_BYTES)
    else:
        return Recovery(
            path, False, max(survey.lengths.values()), survey.rate_hz, {}, survey.status
        )
    if was_open:
        clear_open_flags(path)
        log.info("%s: cleared open-for-write flags 0x%02x", path, sb.flags)
    try:
        status = _repair(path, survey, was_open)
    except (OSError, KeyError, ValueError, RuntimeError) as exc:
        raise RunFileError(
            f"{path}: the repair failed after the superblock was repaired: {exc}"
        ) from exc
    if was_open:
        try:
            release(path)  # the dead writer's space reserved past the end
        except OSError as exc:
            log.warning("%s: could not return the disk space reserved past its end: %s", path, exc)
    return Recovery(path, was_open, max(survey.lengths.values()), survey.rate_hz, padding, status)


def _repair(path: Path, survey: _Survey, was_open: bool) -> str:
    """Pad the short channels with NaN (a ``gap`` event says so) and set the status."""
    lengths, rate = survey.lengths, survey.rate_hz
    n, lo = max(lengths.values()), min(lengths.values())
    padding = survey.padding
    status = survey.status
    with h5py.File(path, "r+") as f:
        g = f["channels"]
        for c, k in padding.items():
            g[c].resize((n,))
            g[c][n - k :] = np.nan
        if padding and survey.events_ok:
            ev = f["events"]
            k = len(ev)
            ev.resize((k + 1,))
            ev[k] = (
                lo / rate,
                fit_utf8("gap", KIND_BYTES),
                fit_utf8(
                    f"samples {lo}..{n} of {', '.join(padding)} lost when the writer stopped",
                    TEXT_BYTES,
                ),
            )
        if was_open or status == STATUS_RECORDING:
            why = status[len("aborted: ") :] + "; " if status.startswith("aborted: ") else ""
            status = (
                f"aborted: {why}not closed by its writer (killed, or its disk filled); {n} samples "
                f"({n / rate:.3f} s) were flushed and kept"
            )
            f.attrs["status"] = status
    return status
