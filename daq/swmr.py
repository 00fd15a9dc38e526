"""Opening a file in SWMR-read mode without HDF5's hour of retries on damaged metadata.

A SWMR reader may read metadata while the writer rewrites it, so HDF5 re-reads a block whose
checksum fails, up to ``H5Pset_metadata_read_attempts`` times (100 by default in SWMR mode)
with a doubling wait from 1 us (``H5_retry``). On a file whose metadata is really damaged (a
writer killed mid-write, a disk that filled) that is a hang: ``fbs inspect`` and ``fbs
recover`` sat over 300 s on one such file. ``READ_ATTEMPTS`` = 30 retries for about 1 s in all
(measured: 25 attempts 0.04 s, 30 1.1 s, 35 34 s), long for a writer's flush, short for a person.

h5py does not wrap ``H5Pset_metadata_read_attempts``; it is called from the HDF5 library h5py
itself loaded (found in this process's memory map). Where it cannot be found, the file is
opened with HDF5's default, as before.
"""

from __future__ import annotations

import ctypes
import functools
import logging
from collections.abc import Callable
from pathlib import Path

import h5py
from h5py import h5f, h5p

log = logging.getLogger(__name__)

#: checksum reads of a block by a SWMR reader: waits doubling from 1 us, about 1 s in all
READ_ATTEMPTS = 30


@functools.cache
def _set_read_attempts() -> Callable[[int, int], int] | None:
    """``H5Pset_metadata_read_attempts`` of the libhdf5 h5py loaded, or None."""
    try:
        maps = Path("/proc/self/maps").read_text()
    except OSError:
        return None
    paths = sorted(
        {
            line.split()[-1]
            for line in maps.splitlines()
            if "libhdf5" in line
            and "hl" not in line.rsplit("/", 1)[-1]
            and line.split()[-1].startswith("/")
        }
    )
    for p in paths:
        try:
            fn = ctypes.CDLL(p).H5Pset_metadata_read_attempts
        except (OSError, AttributeError):
            continue
        fn.argtypes = [ctypes.c_int64, ctypes.c_uint]
        fn.restype = ctypes.c_int
        return fn
    log.debug("H5Pset_metadata_read_attempts not found; SWMR reads keep HDF5's default retries")
    return None


def open_swmr_read(path: str | Path, attempts: int = READ_ATTEMPTS) -> h5py.File:
    """``h5py.File(path, "r", swmr=True)`` with at most ``attempts`` metadata reads per block."""
    fn = _set_read_attempts()
    if fn is None:
        return h5py.File(path, "r", swmr=True)
    fapl = h5p.create(h5p.FILE_ACCESS)
    if fn(fapl.id, attempts) < 0:
        return h5py.File(path, "r", swmr=True)
    fid = h5f.open(str(path).encode(), h5f.ACC_RDONLY | h5f.ACC_SWMR_READ, fapl=fapl)
    return h5py.File(fid)
