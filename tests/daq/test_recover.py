"""Files left by a killed writer: they open in SWMR mode, and ``recover`` makes them plain again."""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import textwrap

import h5py
import numpy as np
import pytest

from daq import runfile
from daq.reader import RunFile
from daq.recover import clear_open_flags, lookup3, read_superblock, recover
from daq.runfile import RunFileError, RunWriter
from fbs.cli import main

# The writer flushes 300 samples, buffers 50 more, and is killed: the 300 must survive.
KILLED_WRITER = textwrap.dedent("""
    import os, signal, sys
    import numpy as np
    from daq.runfile import RunWriter
    w = RunWriter(sys.argv[1], rig="test", mode=3, rate_hz=100.0, channels={"a": "V", "b": "V"})
    x = np.arange(700, dtype=float).reshape(350, 2)
    w.append(x[:300])
    w.event(1.0, "step", "before the kill")
    w.flush()
    w.append(x[300:])
    print("flushed", flush=True)
    if len(sys.argv) > 2:
        sys.stdin.readline()          # stay alive until told
    os.kill(os.getpid(), signal.SIGKILL)
""")

# Low-level: the writer dies between resizing channel a and channel b.
UNEVEN_WRITER = textwrap.dedent("""
    import os, signal, sys
    import h5py, numpy as np
    from daq.runfile import RunWriter
    w = RunWriter(sys.argv[1], rig="test", mode=3, rate_hz=100.0, channels={"a": "V", "b": "V"})
    w.append(np.ones((100, 2)))
    w.flush()
    a = w.datasets[0]
    a.resize((150,)); a[100:] = 2.0
    w.f.flush()
    os.kill(os.getpid(), signal.SIGKILL)
""")


def _allocated_past_end(path) -> int:
    st = os.stat(path)
    return st.st_blocks * 512 - st.st_size


def _run(script: str, path, *extra) -> None:
    p = subprocess.run(
        [sys.executable, "-c", script, str(path), *extra],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert p.returncode == -9, p.stderr


def test_lookup3_matches_bob_jenkins_published_values_and_hdf5():
    # the self-test values printed by lookup3.c's driver5()
    assert lookup3(b"") == 0xDEADBEEF
    assert lookup3(b"", 0xDEADBEEF) == 0xBD5B7DDE
    assert lookup3(b"Four score and seven years ago") == 0x17770551
    assert lookup3(b"Four score and seven years ago", 1) == 0xCD628161


def test_a_fresh_files_superblock_checksum_verifies(tmp_path):
    with h5py.File(tmp_path / "x.h5", "w", libver="latest") as f:
        f["x"] = np.zeros(3)
    sb = read_superblock(tmp_path / "x.h5")  # raises on a checksum mismatch
    assert sb.version >= 2 and sb.flags == 0


def test_a_killed_writers_file_keeps_every_flushed_sample_and_recovers(tmp_path):
    p = tmp_path / "killed.h5"
    _run(KILLED_WRITER, p)
    with pytest.raises(OSError, match="already open for write"):
        h5py.File(p, "r")  # what HDF5 says about a file left open
    with h5py.File(p, "r", swmr=True) as f:  # plain h5py, SWMR-read
        np.testing.assert_array_equal(f["channels/a"][()], np.arange(0, 600, 2))
        assert f.attrs["status"] == "recording" and f.attrs["format"] == "fbs-run"
    with RunFile(p) as run:
        assert run.swmr and run.n_samples == 300
        assert run.status.startswith("aborted: the writer died")  # its pid is gone
        assert [e.text for e in run.events] == ["before the kill"]
    reserved = _allocated_past_end(p)  # the writer reserves space ahead (1 MiB here)
    rec = recover(p)
    assert rec.was_open and rec.samples == 300 and not rec.padded
    assert "300 samples (3.000 s)" in rec.status
    assert _allocated_past_end(p) < min(reserved, 64 << 10) + 4096  # returned by recover
    with h5py.File(p, "r") as f:  # plain open works again
        np.testing.assert_array_equal(f["channels/b"][()], np.arange(1, 600, 2))
        assert f.attrs["status"] == rec.status
    assert read_superblock(p).flags == 0
    again = recover(p)
    assert not again.was_open and "nothing to do" in again.summary()


def test_channels_cut_short_by_the_kill_are_padded_with_nan_not_truncated(tmp_path):
    p = tmp_path / "uneven.h5"
    _run(UNEVEN_WRITER, p)
    rec = recover(p)
    assert rec.samples == 150 and rec.padded == {"b": 50}
    with RunFile(p) as run:
        a, b = run.read(["a", "b"])
        assert (a[100:] == 2.0).all() and np.isnan(b[100:]).all() and (b[:100] == 1.0).all()
        gap = [e for e in run.events if e.kind == "gap"]
        assert gap and gap[0].time_s == 1.0 and "samples 100..150 of b" in gap[0].text


def test_recover_refuses_while_the_writer_runs(tmp_path):
    p = tmp_path / "live.h5"
    with subprocess.Popen(
        [sys.executable, "-c", KILLED_WRITER, str(p), "wait"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    ) as proc:
        try:
            assert proc.stdout.readline().strip() == "flushed"
            with pytest.raises(RunFileError, match=f"pid {proc.pid} .* is still running"):
                recover(p)
            assert read_superblock(p).flags != 0  # untouched
        finally:
            proc.communicate("go\n", timeout=30)
    assert recover(p).samples == 300


def test_not_even_force_repairs_a_file_its_writer_holds_open(tmp_path):
    """Issue 19 item 6: ``recover --force`` under a live writer destroyed its file. force is for
    a pid that only looks alive (another process got the number), not for the writer itself."""
    p = tmp_path / "live.h5"
    with subprocess.Popen(
        [sys.executable, "-c", KILLED_WRITER, str(p), "wait"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    ) as proc:
        try:
            assert proc.stdout.readline().strip() == "flushed"
            before = p.read_bytes()
            with pytest.raises(RunFileError, match="has the file open; stop it first"):
                recover(p, force=True)
            assert p.read_bytes() == before  # untouched
        finally:
            proc.communicate("go\n", timeout=30)
    assert recover(p).samples == 300


def test_force_repairs_a_file_whose_writer_pid_now_names_another_process(tmp_path):
    """The writer is dead but its pid is taken (here: a live process that does not have the file
    open): force repairs it, without force it is refused."""
    p = tmp_path / "dead.h5"
    _run(KILLED_WRITER, p)
    with h5py.File(p, "r", swmr=True) as f:
        writer = f.attrs["writer"]
    import re

    writer = writer if isinstance(writer, str) else writer.decode()
    dead_pid = re.search(r"pid (\d+) on ", writer).group(1)
    # The attribute is patched in place, so the live pid must be no longer than the dead one
    # (zero-padded to its length). This process's pid may not be (the pids wrapped between its
    # start and the writer's: 31692 against 2742 once, and the test was skipped), so a process
    # started after the writer stands in: its pid follows the writer's, and so has its length
    # unless the two straddle a power of ten.
    with subprocess.Popen(
        [sys.executable, "-c", "import sys; sys.stdin.read()"], stdin=subprocess.PIPE
    ) as other:
        try:
            live = next((q for q in (other.pid, os.getpid()) if len(str(q)) <= len(dead_pid)), None)
            if live is None:
                pytest.skip(f"no live pid as short as the dead writer's {dead_pid}")
            taken = str(live).rjust(len(dead_pid), "0")
            _rewrite_writer(p, writer.replace(f"pid {dead_pid} on ", f"pid {taken} on "))
            with pytest.raises(RunFileError, match="is still running; stop it first"):
                recover(p)
            assert recover(p, force=True).samples == 300
        finally:
            other.communicate(b"", timeout=30)


def _rewrite_writer(path, text: str) -> None:
    """Replace the writer attribute in place (same length) without opening the file for writing."""
    with h5py.File(path, "r", swmr=True) as f:
        old = f.attrs["writer"]
    old_b = old.encode() if isinstance(old, str) else bytes(old)
    new_b = text.encode()
    assert len(new_b) == len(old_b)
    data = path.read_bytes()
    assert data.count(old_b) == 1
    path.write_bytes(data.replace(old_b, new_b))


def test_a_damaged_superblock_is_not_touched(tmp_path):
    p = tmp_path / "x.h5"
    with RunWriter(p, rig="t", mode=1, rate_hz=1.0, channels={"a": "V"}) as w:
        w.append(np.zeros((1, 1)))
    raw = bytearray(p.read_bytes())
    raw[20] ^= 0xFF
    p.write_bytes(bytes(raw))
    with pytest.raises(RunFileError, match="checksum mismatch"):
        clear_open_flags(p)
    assert p.read_bytes() == bytes(raw)
    q = tmp_path / "not.h5"
    q.write_bytes(os.urandom(4096))
    with pytest.raises(RunFileError, match="no HDF5 signature"):
        read_superblock(q)


# Killed before its first flush (issue 36 item 8): right after creation, or after a set_meta.
EARLY_KILLED_WRITER = textwrap.dedent("""
    import os, signal, sys
    from daq.runfile import RunWriter
    w = RunWriter(sys.argv[1], rig="test", mode=3, rate_hz=100.0, channels={"a": "V", "b": "rad"},
                  axis="X", procedure="survey", meta={"config": {"gain": 2}}, flush_s=1e6)
    if sys.argv[2] == "meta":
        w.set_meta("acquisition", {"start_unix_s": 1.5})
    os.kill(os.getpid(), signal.SIGKILL)
""")


@pytest.mark.parametrize("last", ["created", "meta"])
def test_a_writer_killed_before_its_first_flush_leaves_a_file_recover_mends(tmp_path, capsys, last):
    """It used to leave 48 bytes (a superblock, nothing else): neither inspect nor recover
    could read it. Now the file has its name only once its layout is on disk."""
    p = tmp_path / "early.h5"
    _run(EARLY_KILLED_WRITER, p, last)
    assert sorted(tmp_path.iterdir()) == [p]  # no temporary file left beside it
    assert main(["inspect", str(p)]) == 2  # not readable as it is; says what is
    err = capsys.readouterr().err
    assert "left open for writing before its first flush" in err and f"`fbs recover {p}`" in err
    assert main(["recover", str(p)]) == 0
    out = capsys.readouterr().out
    assert "recovered; 0 samples per channel (0.000 s) kept" in out
    with h5py.File(p, "r") as f:  # plain h5py, the metadata all there
        a = dict(f.attrs)
        assert (a["format"], a["format_version"], a["rig"], a["mode"]) == ("fbs-run", 1, "test", 3)
        assert (a["axis"], a["procedure"]) == ("X", "survey") and "created" in a
        assert a["status"].startswith("aborted: not closed by its writer")
        assert "0 samples" in a["status"]
        got = {
            c: (len(ds), ds.attrs["units"], ds.attrs["sample_rate_hz"])
            for c, ds in f["channels"].items()
        }
        assert got == {"a": (0, "V", 100.0), "b": (0, "rad", 100.0)}
        meta = {k: json.loads(v) for k, v in f["meta"].attrs.items()}
        assert meta["config"] == {"gain": 2} and "fbs-hil" in meta["software_version"]
        # a set_meta after creation reaches the disk with the first flush: lost here, or whole
        assert meta.get("acquisition", {"start_unix_s": 1.5}) == {"start_unix_s": 1.5}
        assert len(f["events"]) == 0
    assert main(["inspect", str(p)]) == 2  # shown; a run with no samples breaks rule 7
    out, err = capsys.readouterr()
    assert "rig 'test'" in out and "status 'aborted: not closed by its writer" in out
    assert "a  dataset float64 shape (0,); units 'V', sample_rate_hz 100.0" in out
    assert "holds no samples" in err and "Traceback" not in err
    assert not main(["recover", str(p)]) and "nothing to do" in capsys.readouterr().out


# Killed between laying the file out and giving it its name.
UNPUBLISHED_WRITER = textwrap.dedent("""
    import os, signal, sys
    from daq.runfile import RunWriter
    RunWriter._publish = lambda self, overwrite: os.kill(os.getpid(), signal.SIGKILL)
    RunWriter(sys.argv[1], rig="test", mode=3, rate_hz=100.0, channels={"a": "V"}, flush_s=1e6)
""")


def test_a_writer_killed_while_creating_leaves_no_file_and_its_leftover_is_removed(tmp_path):
    p = tmp_path / "r.h5"
    _run(UNPUBLISHED_WRITER, p)
    assert not p.exists()
    left = list(tmp_path.iterdir())
    assert len(left) == 1 and left[0].name.startswith(".r.h5.creating-")  # hidden, and not *.h5
    with RunWriter(p, rig="test", mode=3, rate_hz=100.0, channels={"a": "V"}) as w:
        w.append(np.ones((3, 1)))
    assert sorted(tmp_path.iterdir()) == [p]  # the dead writer's leftover is gone
    with h5py.File(p, "r") as f:
        assert f.attrs["status"] == "complete" and len(f["channels/a"]) == 3


class _RaceLoser(RunWriter):
    """Another program creates the file between the name check and the publishing."""

    def _layout(self, *args) -> None:
        self.path.write_bytes(b"precious")
        super()._layout(*args)


def test_a_file_that_appears_while_the_writer_creates_is_never_overwritten(tmp_path):
    p = tmp_path / "r.h5"
    with pytest.raises(RunFileError, match="exists .*never overwritten"):
        _RaceLoser(p, rig="test", mode=3, rate_hz=100.0, channels={"a": "V"})
    assert p.read_bytes() == b"precious" and sorted(tmp_path.iterdir()) == [p]
    with _RaceLoser(p, rig="test", mode=3, rate_hz=100.0, channels={"a": "V"}, overwrite=True) as w:
        w.append(np.ones((2, 1)))  # asked for: replaced whole
    with h5py.File(p, "r") as f:
        assert len(f["channels/a"]) == 2 and sorted(tmp_path.iterdir()) == [p]


def test_when_the_status_cannot_be_set_the_message_promises_what_recover_does(
    tmp_path, caplog, monkeypatch
):
    p = tmp_path / "r.h5"

    def refuse(path, status):
        raise OSError("no status today")

    monkeypatch.setattr(runfile, "_set_status", refuse)
    with caplog.at_level(logging.ERROR, logger="daq.runfile"):
        with RunWriter(p, rig="test", mode=3, rate_hz=100.0, channels={"a": "V"}) as w:
            w.append(np.ones((7, 1)))
    msg = caplog.records[-1].getMessage()
    assert f"could not set the status of {p} to 'complete': no status today" in msg
    assert f"It still says 'recording'; `fbs recover {p}` marks it aborted, keeping" in msg
    with h5py.File(p, "r") as f:
        assert f.attrs["status"] == "recording"
    rec = recover(p)  # and it does
    assert rec.samples == 7 and rec.status.startswith("aborted: ") and "7 samples" in rec.status
