"""Reserving disk space ahead of a streaming writer (Linux ``fallocate``, size kept), and
refusing a write the disk has no room for before any byte of it is written.

Why reserve: on ext4 a buffered write into blocks not yet allocated pays for delayed
allocation page by page (space reservation, extent-status tree, quota); into blocks reserved
beforehand the same write costs about 30 % less. Measured on this project's VM: 256 MB in
1 MiB ``pwrite`` calls, 0.062 s into a new file, 0.044 s with the space reserved first
(the ``fallocate`` call included). ``FALLOC_FL_KEEP_SIZE`` reserves blocks past the end of
the file without changing its size, so HDF5 and every reader see exactly the file they
would see without it; ``release`` (a truncate to the same size) returns what was not used.

Why refuse: HDF5 does not survive a full disk. A write that fails half-way leaves metadata
(the root group's, a chunk index) half on disk; the file then no longer opens, not even after
``h5clear`` (measured: a 1.6 MB tmpfs, "incorrect metadata checksum" on the root group). So
the disk must never be found full by HDF5: ``reserve`` asks for every byte a write can need,
plus ``headroom_bytes`` that stay reserved for closing the file (the last metadata, the
status attribute), and raises ``DiskFull`` when the filesystem cannot give them. The writer
then writes nothing more and closes the file in the headroom.

Where ``fallocate`` is missing (not Linux, or a filesystem without it), the free space
(``statvfs``) is checked instead: the same refusal, without the guarantee that another
process does not take the room between the check and the write.
"""

from __future__ import annotations

import ctypes
import errno
import logging
import os
import sys
from collections.abc import Callable
from pathlib import Path

log = logging.getLogger(__name__)

#: linux/falloc.h: allocate past the end of file without changing its size.
FALLOC_FL_KEEP_SIZE = 0x01
#: fallocate errors that mean "this filesystem or platform cannot reserve": fall back to statvfs
_UNSUPPORTED = (errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL)


class DiskFull(OSError):
    """The disk has no room for the next write (and its headroom); nothing of it was written."""


def _fallocate() -> Callable[[int, int, int, int], int] | None:
    """glibc's ``fallocate(fd, mode, offset, len)``, or None where there is none."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        fn = ctypes.CDLL(None, use_errno=True).fallocate
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int64, ctypes.c_int64]
    fn.restype = ctypes.c_int
    return fn


class Preallocator:
    """Keeps the next bytes of an open file reserved, ``step_bytes`` at a time, and
    ``headroom_bytes`` beyond every write for closing the file.

    ``fd`` is only used for ``fstat``, ``fstatvfs`` and ``fallocate``; the file's owner
    (HDF5) writes it.
    """

    def __init__(self, fd: int, step_bytes: int, headroom_bytes: int = 0) -> None:
        if step_bytes <= 0:
            raise ValueError(f"preallocation step {step_bytes!r} bytes must be > 0")
        if headroom_bytes < 0:
            raise ValueError(f"headroom {headroom_bytes!r} bytes must be >= 0")
        self.fd = fd
        self.step = int(step_bytes)
        self.headroom = int(headroom_bytes)
        self.reserved = 0  # bytes from 0 reserved so far
        self._call = _fallocate()
        self.enabled = self._call is not None  # reserving (else: checking free space)

    def reserve(self, nbytes: int) -> None:
        """Make sure the ``nbytes`` after the current end of file, and the headroom after
        them, are the file's. Raises ``DiskFull`` (nothing reserved beyond what was) when the
        disk cannot give them."""
        size = os.fstat(self.fd).st_size
        end = size + nbytes + self.headroom
        if end <= self.reserved:
            return
        call = self._call
        if self.enabled and call is not None:
            new = max(end, self.reserved + self.step)
            if call(self.fd, FALLOC_FL_KEEP_SIZE, self.reserved, new - self.reserved) == 0:
                self.reserved = new
                return
            err = ctypes.get_errno()
            if err in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
                if (
                    new > end
                    and call(self.fd, FALLOC_FL_KEEP_SIZE, self.reserved, end - self.reserved) == 0
                ):
                    self.reserved = end  # the step was too much, what is needed fits
                    return
                raise self._no_room(err, nbytes, os.strerror(err))
            self.enabled = False
            if err not in _UNSUPPORTED and err != errno.EINTR:
                log.warning(
                    "fallocate failed: %s; checking the free space instead of reserving it",
                    os.strerror(err),
                )
            else:
                log.debug(
                    "not reserving disk space ahead (fallocate: %s); checking the free space",
                    os.strerror(err),
                )
        st = os.fstatvfs(self.fd)
        free = st.f_bavail * st.f_frsize
        if free < end - max(size, self.reserved):
            raise self._no_room(errno.ENOSPC, nbytes, f"{free} bytes free")

    def truncated(self) -> None:
        """The file's owner truncated it: blocks reserved past its new end went back to the
        disk (HDF5 shrinks a file to its end of address space at some flushes), so they are
        reserved no longer and the next ``reserve`` asks for them again."""
        self.reserved = min(self.reserved, os.fstat(self.fd).st_size)

    def _no_room(self, err: int, nbytes: int, why: str) -> DiskFull:
        return DiskFull(
            err,
            f"no room for {nbytes + self.headroom} more bytes ({nbytes} to write, "
            f"{self.headroom} kept to close the file): {why}",
        )


def release(path: str | Path) -> None:
    """Return the blocks reserved past the end of ``path`` (a truncate to its own size)."""
    os.truncate(path, os.stat(path).st_size)
