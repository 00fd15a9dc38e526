"""A disk that fills for real (a small tmpfs, issue 19 point 1 and acceptance C): the writer
stops before HDF5 meets the full disk and closes the file in the room it kept; ``recover``
refuses, writing nothing, where it cannot succeed, and recovers a copy on a disk with room.

Before this, the same tmpfs left a file whose root group no longer opened ("incorrect metadata
checksum") and a recover that died on it; only the ``ulimit -f`` path recovered."""

from __future__ import annotations

import hashlib
import json
import logging
import shutil
import signal
import subprocess
import sys
import textwrap

import h5py
import numpy as np
import pytest

from daq.recover import recover
from daq.runfile import RunFileError, RunWriter

RATE = 400.0
N_CH = 17  # as many channels as a rig records
BLOCK = 400  # samples per append


def _value(i: int) -> float:
    return float(i) + 0.25


def _sha(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _fbs(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "fbs.cli", *args], capture_output=True, text=True, timeout=300
    )


def _check_samples(path, n: int) -> None:
    """The first ``n`` samples of every channel read back as written (block i holds i + 0.25)."""
    with h5py.File(path, "r") as f:
        for c in f["channels"]:
            x = f["channels"][c][:n]
            assert len(x) == n, (c, len(x), n)
            assert np.array_equal(x, np.repeat([_value(i) for i in range(n // BLOCK)], BLOCK)), c


def test_a_writer_stops_before_the_full_disk_reaches_hdf5_and_the_file_opens(small_disk):
    disk = small_disk(2 << 20)
    p = disk.path / "run.h5"
    w = RunWriter(
        p,
        rig="test",
        mode=3,
        rate_hz=RATE,
        channels={f"c{i}": "V" for i in range(N_CH)},
        clock=lambda: 0.0,
    )
    disk.fill(leave_bytes=900_000)  # another program takes the disk while we record
    with pytest.raises(RunFileError) as err:
        for i in range(10_000):
            w.append(np.full((BLOCK, N_CH), _value(i)))
            w.flush()
    msg = str(err.value)
    assert "the disk is full" in msg and "Free some space or record to another disk" in msg
    flushed = int(msg.split("Samples 0..")[1].split(" ")[0])
    assert flushed == w.flushed >= 2 * BLOCK
    with pytest.raises(RunFileError):
        w.close()  # the failure is not forgotten at close
    assert disk.free() < 400_000  # still full: the close used the room it kept
    with h5py.File(p, "r") as f:  # plain h5py, no recovery needed
        assert (
            f.attrs["status"].startswith("aborted: writing")
            and "the disk is full" in f.attrs["status"]
        )
        assert {len(f["channels"][c]) for c in f["channels"]} == {flushed}
    _check_samples(p, flushed)
    before = _sha(p)
    rec = recover(p)  # in place on the full disk: nothing to do
    assert not rec.was_open and _sha(p) == before


_CHANNELS = {f"c{i}": "V" for i in range(N_CH)}


@pytest.mark.parametrize("leave", [0, 100_000])
def test_no_room_to_create_and_close_a_file_leaves_nothing_behind(small_disk, leave):
    """Issue 36 item 8: a disk too full for the file and the room to close it refuses the
    recording at once, rather than leaving a file that could not be closed (or recovered)."""
    disk = small_disk(2 << 20)
    disk.fill(leave_bytes=leave)
    p = disk.path / "run.h5"
    with pytest.raises(RunFileError, match=f"cannot create run file {p}.*the disk is full"):
        RunWriter(p, rig="test", mode=3, rate_hz=RATE, channels=_CHANNELS)
    assert sorted(q.name for q in disk.path.iterdir()) == ["ballast0"]


def test_a_disk_full_before_the_first_flush_still_closes_the_file_with_status(small_disk, caplog):
    """The room to close in is reserved when the file is created: a disk taken before the
    first write still gets the status and every metadata written, and no "recover later"."""
    disk = small_disk(2 << 20)
    p = disk.path / "run.h5"
    w = RunWriter(
        p,
        rig="test",
        mode=3,
        rate_hz=RATE,
        channels=_CHANNELS,
        meta={"config": {"gain": 2}},
        clock=lambda: 0.0,
    )
    w.set_meta("acquisition", {"start_unix_s": 1.5})
    disk.fill()  # all of it, before anything was written
    with caplog.at_level(logging.WARNING, logger="daq.runfile"):
        with pytest.raises(RunFileError, match="the disk is full") as err:
            w.append(np.full((20 * BLOCK, N_CH), _value(0)))  # more than was reserved ahead
            w.flush()
        assert "Samples 0..0 (0.000 s) were flushed before" in str(err.value)
        with pytest.raises(RunFileError):
            w.close()
    assert not caplog.records, [r.getMessage() for r in caplog.records]
    with h5py.File(p, "r") as f:  # plain h5py, no recovery needed
        status = f.attrs["status"]
        assert status.startswith("aborted: writing") and "the disk is full" in status
        assert {len(f["channels"][c]) for c in f["channels"]} == {0}
        assert json.loads(f["meta"].attrs["acquisition"]) == {"start_unix_s": 1.5}
        assert json.loads(f["meta"].attrs["config"]) == {"gain": 2}
    assert not recover(p).was_open


_KILLED_WRITER = textwrap.dedent("""
    import sys, time, numpy as np
    from daq.runfile import RunWriter
    w = RunWriter(sys.argv[1], rig="test", mode=3, rate_hz={rate}, channels={{f"c{{i}}": "V" for i in range({n})}})
    for i in range(int(sys.argv[2])):
        w.append(np.full(({block}, {n}), i + 0.25))
        w.flush()
    print(w.flushed, flush=True)
    time.sleep(600)
""").format(rate=RATE, n=N_CH, block=BLOCK)


def _killed_writer(path, blocks: int) -> int:
    """A writer SIGKILLed after flushing ``blocks`` blocks; returns the samples it flushed."""
    with subprocess.Popen(
        [sys.executable, "-c", _KILLED_WRITER, str(path), str(blocks)],
        stdout=subprocess.PIPE,
        text=True,
    ) as proc:
        try:
            assert proc.stdout is not None
            flushed = int(proc.stdout.readline())
        finally:
            proc.send_signal(signal.SIGKILL)
            proc.wait()
    return flushed


def test_recover_on_the_full_disk_refuses_writing_nothing_and_recovers_a_copy(small_disk, tmp_path):
    disk = small_disk(2 << 20)
    p = disk.path / "run.h5"
    flushed = _killed_writer(p, 6)
    assert flushed == 6 * BLOCK
    disk.fill()
    before = _sha(p)
    done = _fbs("recover", str(p))
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert (
        "Nothing was written; copy the file to a disk with room and recover the copy" in done.stderr
    )
    assert _sha(p) == before
    copy = tmp_path / "copy.h5"
    shutil.copyfile(p, copy)
    done = _fbs("recover", str(copy))
    assert done.returncode == 0, done.stderr
    assert f"{flushed} samples per channel" in done.stdout
    _check_samples(copy, flushed)


def test_recover_refuses_a_file_whose_metadata_a_failed_write_damaged(tmp_path):
    p = tmp_path / "run.h5"
    flushed = _killed_writer(p, 3)
    assert flushed == 3 * BLOCK
    raw = bytearray(p.read_bytes())
    root = int.from_bytes(
        raw[raw.index(b"\x89HDF\r\n\x1a\n") + 36 :][:8], "little"
    )  # root object header
    assert raw[root : root + 4] == b"OHDR"
    raw[root + 8 : root + 24] = bytes(16)  # as a write cut short by a full disk
    p.write_bytes(bytes(raw))
    before = _sha(p)
    done = _fbs("recover", str(p))
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert "metadata cannot be read" in done.stderr and "Nothing was written" in done.stderr
    assert _sha(p) == before
