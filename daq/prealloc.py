"""Reserving disk space ahead of a streaming writer (Linux ``fallocate``, size kept).

Why: on ext4 a buffered write into blocks not yet allocated pays for delayed allocation
page by page (space reservation, extent-status tree, quota); into blocks reserved
beforehand the same write costs about 30 % less. Measured on this project's VM: 256 MB in
1 MiB ``pwrite`` calls, 0.062 s into a new file, 0.044 s with the space reserved first
(the ``fallocate`` call included). ``FALLOC_FL_KEEP_SIZE`` reserves blocks past the end of
the file without changing its size, so HDF5 and every reader see exactly the file they
would see without it; ``release`` (a truncate to the same size) returns what was not used.

Where ``fallocate`` is missing (not Linux, or a filesystem without it) or fails (the disk
is full), reserving stops, quietly: the writes themselves still report a full disk.
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
    """Keeps the next bytes of an open file reserved, ``step_bytes`` at a time.

    ``fd`` is only used for ``fstat`` and ``fallocate``; the file's owner (HDF5) writes it.
    """

    def __init__(self, fd: int, step_bytes: int) -> None:
        if step_bytes <= 0:
            raise ValueError(f"preallocation step {step_bytes!r} bytes must be > 0")
        self.fd = fd
        self.step = int(step_bytes)
        self.reserved = 0           # bytes from 0 reserved so far
        self._call = _fallocate()
        self.enabled = self._call is not None

    def reserve(self, nbytes: int) -> None:
        """Make sure the ``nbytes`` after the current end of file are reserved."""
        call = self._call
        if not self.enabled or call is None:  # enabled only where there is a fallocate
            return
        end = os.fstat(self.fd).st_size + nbytes
        if end <= self.reserved:
            return
        new = max(end, self.reserved + self.step)
        if call(self.fd, FALLOC_FL_KEEP_SIZE, self.reserved, new - self.reserved) != 0:
            err = ctypes.get_errno()
            self.enabled = False
            log.debug("not reserving disk space ahead any more (fallocate: %s)", os.strerror(err))
            if err not in (errno.EOPNOTSUPP, errno.ENOSYS, errno.ENOSPC, errno.EFBIG, errno.EINTR):
                log.warning("fallocate failed: %s; writing on without reserving space", os.strerror(err))
            return
        self.reserved = new


def release(path: str | Path) -> None:
    """Return the blocks reserved past the end of ``path`` (a truncate to its own size)."""
    os.truncate(path, os.stat(path).st_size)
