"""Reserving disk space past the end of a file without changing its size, and returning it."""

from __future__ import annotations

import logging
import os

import pytest

from daq.prealloc import Preallocator, release

MiB = 1 << 20


def _allocated(fd: int) -> int:
    return os.fstat(fd).st_blocks * 512


def test_reserve_keeps_the_size_steps_ahead_and_release_returns_the_rest(tmp_path):
    p = tmp_path / "f.bin"
    p.write_bytes(b"x" * 10_000)
    fd = os.open(p, os.O_RDWR)
    try:
        pre = Preallocator(fd, MiB)
        pre.reserve(5000)
        if not pre.enabled:
            pytest.skip("this filesystem cannot reserve space (fallocate)")
        assert os.fstat(fd).st_size == 10_000 and pre.reserved == MiB and _allocated(fd) >= MiB
        pre.reserve(MiB - 10_000)  # still inside: nothing to do
        assert pre.reserved == MiB
        os.pwrite(fd, b"y" * (3 * MiB // 2), 10_000)  # the file grows past the reservation
        pre.reserve(MiB)
        end = 10_000 + 3 * MiB // 2 + MiB
        assert pre.reserved == end and _allocated(fd) >= end
        assert os.pread(fd, 4, 10_000) == b"yyyy"
    finally:
        os.close(fd)
    release(p)
    st = os.stat(p)
    assert st.st_size == 10_000 + 3 * MiB // 2 and st.st_blocks * 512 < st.st_size + 64 * 1024


def test_after_the_owner_shrinks_the_file_what_it_returned_is_asked_for_again(tmp_path):
    """HDF5 truncates a file to its end of address space at some flushes (the switch to SWMR
    after the creation flush); a shrinking truncate returns the blocks reserved past it."""
    p = tmp_path / "f.bin"
    p.write_bytes(b"x" * 20_000)
    fd = os.open(p, os.O_RDWR)
    try:
        pre = Preallocator(fd, MiB, headroom_bytes=4096)
        pre.reserve(0)
        if not pre.enabled:
            pytest.skip("this filesystem cannot reserve space (fallocate)")
        assert pre.reserved == MiB and _allocated(fd) >= MiB
        os.ftruncate(fd, 10_000)
        assert _allocated(fd) < 64 * 1024  # what the reservation was counting on
        pre.truncated()
        assert pre.reserved == 10_000
        pre.reserve(0)
        assert pre.reserved == 10_000 + MiB and _allocated(fd) >= 10_000 + MiB
    finally:
        os.close(fd)


def test_a_failing_fallocate_stops_reserving_and_says_why(tmp_path, caplog):
    p = tmp_path / "f.bin"
    p.write_bytes(b"x")
    fd = os.open(p, os.O_RDONLY)  # fallocate on it: EBADF
    try:
        pre = Preallocator(fd, MiB)
        if not pre.enabled:
            pytest.skip("no fallocate on this platform")
        with caplog.at_level(logging.WARNING, logger="daq.prealloc"):
            pre.reserve(10)
            pre.reserve(10)
        assert not pre.enabled and pre.reserved == 0
        assert [r.getMessage() for r in caplog.records] == [
            "fallocate failed: Bad file descriptor; checking the free space instead of reserving it"
        ]
    finally:
        os.close(fd)


def test_a_step_must_be_positive():
    with pytest.raises(ValueError, match="preallocation step 0 bytes must be > 0"):
        Preallocator(0, 0)
