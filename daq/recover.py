"""Recover a run file whose writer died (SIGKILL, power cut, full disk) before closing it.

An SWMR writer marks the HDF5 superblock "open for writing" and leaves the end-of-file
address stale until it closes. A killed writer's file therefore opens only in SWMR-read
mode; plain ``h5py.File(path)`` refuses it ("file is already open for write (may use
<h5clear file> ...)"). ``recover`` does what ``h5clear -s --increment`` does, in place:

1. find the superblock (version 2 or 3, 8-byte addresses), check its checksum;
2. clear the file-consistency flags, set the end-of-file address to the file's size and
   write the new checksum (Jenkins' lookup3, as HDF5 computes it);
3. reopen with plain h5py: channels of unequal length (the writer died between two of
   them) are padded with NaN to the longest, with a ``gap`` event, so no sample is
   dropped; the status becomes "aborted: ..." with the number of samples kept.

It refuses a file whose writer is still running on this host.
"""

from __future__ import annotations

import logging
import os
import re
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from daq.prealloc import release
from daq.reader import RunFile
from daq.runfile import EVENT_DTYPE, KIND_BYTES, STATUS_RECORDING, TEXT_BYTES, RunFileError, fit_utf8

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
    words = [int.from_bytes(padded[i:i + 4], "little") for i in range(0, len(padded), 4)]
    blocks = [words[i:i + 3] for i in range(0, len(words), 3)]
    if not blocks:
        return v[2]
    for blk in blocks[:-1]:
        v = [(v[j] + blk[j]) & _M32 for j in range(3)]
        for x, y, z, r in _MIX:          # x -= y; x ^= rot(y, r); y += z
            v[x] = ((v[x] - v[y]) & _M32) ^ _rot(v[y], r)
            v[y] = (v[y] + v[z]) & _M32
    v = [(v[j] + blocks[-1][j]) & _M32 for j in range(3)]
    for x, y, r in _FINAL:               # x ^= y; x -= rot(y, r)
        v[x] = ((v[x] ^ v[y]) - _rot(v[y], r)) & _M32
    return v[2]


@dataclass(frozen=True)
class Superblock:
    offset: int          # where the signature is (0, 512, 1024, ...)
    version: int
    flags: int           # file-consistency flags: non-zero while a writer has the file
    base: int            # base address: file addresses count from here
    eof: int             # end-of-file address, relative to base

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
                break
            offset = 512 if offset == 0 else offset * 2
        else:
            raise RunFileError(f"{path}: no HDF5 signature found; not an HDF5 file")
    version = raw[8]
    if version not in (2, 3):
        raise RunFileError(f"{path}: superblock version {version} has no open-for-write flags to clear "
                           "(only versions 2 and 3 do)")
    if raw[9] != 8 or raw[10] != 8:
        raise RunFileError(f"{path}: {raw[9]}-byte offsets / {raw[10]}-byte lengths are not supported (8/8 only)")
    stored = int.from_bytes(raw[44:48], "little")
    if lookup3(raw[:44]) != stored:
        raise RunFileError(f"{path}: superblock checksum mismatch; the file is damaged beyond this repair")
    return Superblock(offset, version, raw[11], int.from_bytes(raw[12:20], "little"),
                      int.from_bytes(raw[28:36], "little"))


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
        raw = bytearray(fh.read(48))
        raw[11] = 0
        if sb.eof > size - sb.base:
            fh.truncate(sb.base + sb.eof)
            log.warning("%s: zero-filled %d bytes up to the recorded end of file", path, sb.base + sb.eof - size)
        raw[28:36] = max(sb.eof, size - sb.base).to_bytes(8, "little")
        raw[44:48] = lookup3(bytes(raw[:44])).to_bytes(4, "little")
        fh.seek(sb.offset)
        fh.write(raw)
        fh.flush()
        os.fsync(fh.fileno())
    return sb


@dataclass
class Recovery:
    path: Path
    was_open: bool              # the flags said open for writing
    samples: int                # samples per channel now in the file
    rate_hz: float
    padded: dict[str, int]      # channel -> NaN samples added to reach the longest
    status: str

    def summary(self) -> str:
        if not self.was_open:
            return f"{self.path}: was closed properly; status {self.status!r}; nothing to do"
        pad = (", padded with NaN: " + ", ".join(f"{c} +{n}" for c, n in self.padded.items())) if self.padded else ""
        return (f"{self.path}: recovered; {self.samples} samples per channel ({self.samples / self.rate_hz:.3f} s) "
                f"kept{pad}; status {self.status!r}; opens with plain h5py now")


def _refuse_if_writer_alive(path: Path, *, force: bool) -> None:
    """Refuse a file whose writer still runs. ``force`` overrides a writer that is only *said*
    to run (its pid alive on this host: perhaps another process got the number), never one
    that holds this very file open (``_holds_open``): that is the writer, and clearing its
    flags under it destroyed the file."""
    try:
        with RunFile(path) as run:       # opens in SWMR mode, as a live writer's file must be
            alive = run.writer_alive()
            writer = str(run.attrs.get("writer", "?"))
    except RunFileError as exc:          # unreadable even so: no live writer keeps it that way
        log.warning("%s: cannot tell whether its writer runs (%s); repairing", path, exc)
        return
    if not alive:
        return
    m = _WRITER_PID.search(writer)
    if m and _holds_open(int(m.group(1)), path):
        raise RunFileError(f"{path}: its writer ({writer}) is still running and has the file open; stop it "
                           f"first (not even force repairs a file under its writer)")
    if not force:
        raise RunFileError(f"{path}: its writer ({writer}) is still running; stop it first "
                           "(or pass force if that process is not the writer)")


_WRITER_PID = re.compile(r"pid (\d+) on ")


def _holds_open(pid: int, path: Path) -> bool:
    """Whether process ``pid`` has ``path`` open (Linux /proc; False where that cannot be seen)."""
    target = path.resolve()
    try:
        fds = list(Path(f"/proc/{pid}/fd").iterdir())
    except OSError:
        return False
    for fd in fds:
        try:
            if Path(os.readlink(fd)) == target:
                return True
        except OSError:
            continue
    return False


def recover(path: str | Path, *, force: bool = False) -> Recovery:
    """Make a file left by a dead writer open with plain h5py, keeping every flushed sample."""
    path = Path(path)
    sb = read_superblock(path)
    was_open = sb.needs_repair(path.stat().st_size)
    if was_open:
        if sb.flags:
            _refuse_if_writer_alive(path, force=force)
        clear_open_flags(path)
        log.info("%s: cleared open-for-write flags 0x%02x", path, sb.flags)
    padded: dict[str, int] = {}
    with h5py.File(path, "r+") as f:
        status = f.attrs.get("status", "")
        status = status.decode() if isinstance(status, bytes) else str(status)
        g = f["channels"]
        rate = float(g[next(iter(g))].attrs["sample_rate_hz"])
        lengths = {c: g[c].shape[0] for c in g}
        n = max(lengths.values())
        for c, m in lengths.items():
            if m < n:
                g[c].resize((n,))
                g[c][m:] = np.nan
                padded[c] = n - m
        if padded and "events" in f and f["events"].dtype == EVENT_DTYPE:
            ev = f["events"]
            k = len(ev)
            ev.resize((k + 1,))
            lo = min(lengths.values())
            ev[k] = (lo / rate, fit_utf8("gap", KIND_BYTES),
                     fit_utf8(f"samples {lo}..{n} of {', '.join(padded)} lost when the writer stopped", TEXT_BYTES))
        if was_open or status == STATUS_RECORDING:
            why = status[len("aborted: "):] + "; " if status.startswith("aborted: ") else ""
            status = (f"aborted: {why}not closed by its writer (killed, or its disk filled); {n} samples "
                      f"({n / rate:.3f} s) were flushed and kept")
            f.attrs["status"] = status
    if was_open:
        try:
            release(path)               # the dead writer's space reserved past the end
        except OSError as exc:
            log.warning("%s: could not return the disk space reserved past its end: %s", path, exc)
    return Recovery(path, was_open, n, rate, padded, status)
