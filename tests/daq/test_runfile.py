"""The streaming writer: layout, flush policy, refusal to overwrite, abort status, event strings."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from daq.prealloc import Preallocator
from daq.runfile import (
    EVENT_DTYPE,
    TEXT_BYTES,
    RunFileError,
    RunWriter,
    check_new_path,
    chunk_samples,
    fit_utf8,
)


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _writer(path, clock=None, **kw) -> RunWriter:
    kw = {"rig": "test", "mode": 3, "rate_hz": 100.0, "channels": {"a": "V", "b": "rad"}} | kw
    return RunWriter(path, clock=clock or Clock(), **kw)


def test_a_closed_file_follows_the_layout_and_opens_with_plain_h5py(tmp_path):
    rng = np.random.default_rng(1)
    x = rng.standard_normal((250, 2))
    with _writer(
        tmp_path / "r.h5", axis="X", procedure="unit", meta={"calibration": {"K": 1.5}}
    ) as w:
        w.set_meta("acquisition", {"start_rig_s": 2.0})
        w.append(x[:100])
        w.append({"a": x[100:200, 0], "b": x[100:200, 1]})
        w.append_missing(7)
        w.append(x[200:])
        w.event(1.0, "mode", "mode 3")
    with h5py.File(tmp_path / "r.h5", "r") as f:  # plain: no SWMR flag, no recovery
        a = f.attrs
        assert (
            a["format"],
            a["format_version"],
            a["rig"],
            a["mode"],
            a["axis"],
            a["procedure"],
            a["status"],
        ) == ("fbs-run", 1, "test", 3, "X", "unit", "complete")
        assert a["created"].endswith("+00:00") and "pid" in a["writer"]
        ga, gb = f["channels/a"], f["channels/b"]
        assert (
            ga.attrs["units"] == "V"
            and gb.attrs["units"] == "rad"
            and ga.attrs["sample_rate_hz"] == 100.0
        )
        assert ga.dtype == np.float64 and ga.ndim == 1 and ga.maxshape == (None,) and ga.chunks
        np.testing.assert_array_equal(ga[:200], x[:200, 0])
        assert np.isnan(gb[200:207]).all()
        np.testing.assert_array_equal(gb[207:], x[200:, 1])
        assert f["events"][0]["kind"] == b"mode" and f["events"][0]["time"] == 1.0
        assert json.loads(f["meta"].attrs["calibration"]) == {"K": 1.5}
        assert json.loads(f["meta"].attrs["acquisition"]) == {"start_rig_s": 2.0}
        assert "fbs-hil" in json.loads(f["meta"].attrs["software_version"])


def test_the_writer_keeps_to_hdf5_1_10_format_bounds(tmp_path):
    """DESIGN.md section 6: encodings HDF5 1.10 reads (with "latest" the installed 2.x library
    chose newer ones for the events table, which h5dump 1.10.8 refused)."""
    with _writer(tmp_path / "r.h5") as w:
        assert w.f.id.get_access_plist().get_libver_bounds() == (
            h5py.h5f.LIBVER_V110,
            h5py.h5f.LIBVER_V110,
        )
        w.append(np.zeros((10, 2)))
        w.event(0.5, "mode", "mode 3")


def _h5dump_1_10() -> str | None:
    import shutil

    exe = shutil.which("h5dump")
    if exe is None:
        return None
    out = subprocess.run([exe, "--version"], capture_output=True, text=True, timeout=30).stdout
    return exe if "1.10." in out else None


@pytest.mark.skipif(
    _h5dump_1_10() is None, reason="no HDF5 1.10 h5dump on PATH to read the file with"
)
def test_a_run_file_opens_in_hdf5_1_10_h5dump(tmp_path):
    """Issue 19 acceptance E: the file, events table included, dumps with HDF5 1.10's tool."""
    with _writer(tmp_path / "r.h5", axis="X", procedure="unit") as w:
        w.append(np.zeros((10, 2)))
        w.event(0.5, "mode", "mode 3")
    r = subprocess.run(
        [str(_h5dump_1_10()), "-H", str(tmp_path / "r.h5")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    assert "events" in r.stdout


def test_samples_are_written_when_the_buffer_fills_and_flushed_when_the_interval_passes(tmp_path):
    clock = Clock()
    w = _writer(
        tmp_path / "r.h5", clock, flush_s=0.5, buffer_bytes=16 * 100
    )  # 100 samples of 2 channels
    w.append(np.zeros((30, 2)))
    w.sync()
    assert (w.flushed, w.samples) == (0, 30)
    clock.t = 0.49
    w.append(np.zeros((30, 2)))
    w.sync()
    assert w.flushed == 0
    clock.t = 0.5
    w.append(np.zeros((10, 2)))
    w.sync()  # the write thread has done what was handed over
    assert w.flushed == 70  # the interval passed: everything went out
    w.append(np.ones((250, 2)))  # buffers fill within the interval, ending on
    w.sync()  # multiples of their size: 70..100, 100..200, 200..300
    assert (w.written, w.flushed, w.samples) == (300, 70, 320)  # written, not yet flushed
    clock.t = 1.0
    w.event(0.9, "note", "operator note")  # an event alone also flushes when due
    w.sync()
    assert w.flushed == w.written == 320
    w.close()
    with h5py.File(tmp_path / "r.h5") as f:
        assert len(f["channels/a"]) == 320 and f["channels/a"][70:320].sum() == 250
        assert len(f["events"]) == 1


def test_a_live_reader_does_not_keep_the_status_from_being_set(tmp_path):
    p = tmp_path / "r.h5"
    w = _writer(p)
    w.append(np.ones((5, 2)))
    w.flush()
    code = (
        "import sys, time, h5py; f = h5py.File(sys.argv[1], 'r', swmr=True); print('open', flush=True); "
        "sys.stdin.readline()"
    )
    with subprocess.Popen(
        [sys.executable, "-c", code, str(p)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    ) as reader:
        try:
            assert reader.stdout.readline().strip() == "open"
            w.close()
        finally:
            reader.communicate("\n", timeout=30)
    with h5py.File(p) as f:
        assert f.attrs["status"] == "complete" and len(f["channels/b"]) == 5


def test_set_meta_is_refused_once_streaming(tmp_path):
    with _writer(tmp_path / "r.h5") as w:
        w.append(np.zeros((1, 2)))
        w.flush()
        with pytest.raises(RuntimeError, match="before the first sample"):
            w.set_meta("late", 1)


def test_an_existing_file_is_never_overwritten_unless_asked(tmp_path):
    p = tmp_path / "r.h5"
    with _writer(p) as w:
        w.append(np.ones((5, 2)))
    with pytest.raises(RunFileError, match="exists; a recording is never overwritten"):
        _writer(p)
    with h5py.File(p) as f:
        assert len(f["channels/a"]) == 5  # untouched
    with _writer(p, overwrite=True) as w:
        w.append(np.ones((2, 2)))
    with h5py.File(p) as f:
        assert len(f["channels/a"]) == 2


def test_bad_paths_are_named(tmp_path):
    (tmp_path / "afile").write_text("x")
    with pytest.raises(RunFileError, match="afile"):
        check_new_path(tmp_path / "afile" / "r.h5")
    with pytest.raises(RunFileError, match="is a directory"):
        _writer(tmp_path)


def test_an_exception_closes_the_file_aborted_with_the_reason(tmp_path):
    with pytest.raises(ZeroDivisionError):
        with _writer(tmp_path / "r.h5") as w:
            w.append(np.ones((3, 2)))
            raise ZeroDivisionError("division by zero")
    with h5py.File(tmp_path / "r.h5") as f:
        assert f.attrs["status"] == "aborted: ZeroDivisionError: division by zero"
        assert len(f["channels/a"]) == 3


@pytest.mark.parametrize(
    "block, match",
    [
        (np.zeros((3, 3)), r"\(n, 2\)"),
        ({"a": np.zeros(3)}, "exactly the channels"),
        ({"a": np.zeros(3), "b": np.zeros(4)}, "different lengths"),
    ],
)
def test_malformed_blocks_are_refused(tmp_path, block, match):
    with _writer(tmp_path / "r.h5") as w:
        with pytest.raises(ValueError, match=match):
            w.append(block)


def test_bad_construction_arguments_are_refused_before_a_file_exists(tmp_path):
    for kw, match in [
        ({"rate_hz": 0.0}, "sample rate"),
        ({"channels": {}}, "at least one channel"),
        ({"channels": {"a/b": "V"}}, "cannot name"),
        ({"flush_s": 0}, "flush interval"),
    ]:
        with pytest.raises(ValueError, match=match):
            _writer(tmp_path / "r.h5", **kw)
    assert not (tmp_path / "r.h5").exists()


def test_chunks_track_one_flush_of_samples():
    assert chunk_samples(10.0, 0.5) == 1024
    assert chunk_samples(10_000.0, 0.5) == 8192
    assert chunk_samples(1e6, 0.5) == 131072


@given(st.text(max_size=2000), st.integers(8, 1100))
def test_fit_utf8_keeps_short_text_and_cuts_long_text_at_a_character(text, limit):
    out = fit_utf8(text, limit)
    assert len(out) <= limit
    decoded = out.decode("utf-8")  # never a broken character
    if len(text.encode()) <= limit:
        assert decoded == text
    else:
        assert decoded.endswith(" [cut]") and text.startswith(decoded[: -len(" [cut]")])


def test_a_long_event_text_is_cut_and_marked(tmp_path):
    with _writer(tmp_path / "r.h5") as w:
        w.event(0.0, "error", "é" * TEXT_BYTES)
    with h5py.File(tmp_path / "r.h5") as f:
        assert f["events"].dtype == EVENT_DTYPE
        text = f["events"][0]["text"].decode()
        assert text.endswith("[cut]") and len(text.encode()) <= TEXT_BYTES


@settings(max_examples=25, deadline=None)
@given(
    st.lists(st.tuples(st.integers(1, 5000), st.booleans()), min_size=1, max_size=12),
    st.integers(1000, 6000),
)
def test_any_sequence_of_appends_and_flushes_reads_back_exactly(tmp_path_factory, steps, cap):
    """Whole chunks (1024 samples here) go by H5Dwrite_chunk, partial ones by H5Dwrite, from any
    alignment a buffer of ``cap`` samples and flushes at any point leave them in."""
    p = tmp_path_factory.mktemp("w") / "r.h5"
    clock = Clock()
    rng = np.random.default_rng(len(steps) * cap)
    sent = []
    with _writer(p, clock, buffer_bytes=16 * cap) as w:
        for n, flush_due in steps:
            x = rng.standard_normal((n, 2))
            sent.append(x)
            if flush_due:
                clock.t += 0.5
            w.append(x)
    x = np.concatenate(sent)
    with h5py.File(p) as f:
        assert f["channels/a"].chunks == (1024,)
        np.testing.assert_array_equal(f["channels/a"][:], x[:, 0])
        np.testing.assert_array_equal(f["channels/b"][:], x[:, 1])


class _LayoutFails(RunWriter):
    def _layout(self, *args) -> None:
        raise OSError(
            "Unable to create group (file write failed: errno = 28, error message = 'No space left')"
        )


def test_a_layout_that_fails_is_a_clear_error_and_leaves_no_file(tmp_path):
    p = tmp_path / "r.h5"
    with pytest.raises(RunFileError, match=r"cannot lay out run file .*r\.h5 \(the disk is full\)"):
        _LayoutFails(p, rig="test", mode=3, rate_hz=100.0, channels={"a": "V"}, clock=Clock())
    assert not p.exists()
    with _writer(p) as w:  # and the name can be used again
        w.append(np.ones((2, 2)))


class _WriteFails(RunWriter):
    def _write_channel(self, did, x, n0) -> None:
        raise OSError(
            "Can't write data (file write failed: errno = 28, error message = 'No space left')"
        )


def test_close_raises_a_write_failure_that_no_call_reported(tmp_path):
    p = tmp_path / "r.h5"
    w = _WriteFails(
        p,
        rig="test",
        mode=3,
        rate_hz=100.0,
        channels={"a": "V"},
        clock=Clock(),
        buffer_bytes=8 * 10,
    )
    w.append(np.zeros((10, 1)))  # a full buffer: handed to the write thread, which fails
    deadline = time.monotonic() + 60  # a hang guard, not a timing assert
    while (
        w.failed is None and time.monotonic() < deadline
    ):  # on the write thread; no call has seen it
        time.sleep(0.001)
    assert w.failed is not None
    with pytest.raises(RunFileError, match="the disk is full"):
        w.close()
    with h5py.File(p) as f:
        assert f.attrs["status"].startswith("aborted: writing") and len(f["channels/a"]) == 0


def _fallocate_works(folder) -> bool:
    probe = folder / "probe.bin"
    probe.write_bytes(b"\0")
    fd = os.open(probe, os.O_RDWR)
    try:
        pre = Preallocator(fd, 1 << 20)
        pre.reserve(1)
        return pre.enabled and os.fstat(fd).st_blocks * 512 >= 1 << 20
    finally:
        os.close(fd)
        probe.unlink()


def test_disk_space_is_reserved_ahead_while_recording_and_returned_at_close(tmp_path):
    if not _fallocate_works(tmp_path):
        pytest.skip("this filesystem cannot reserve space (fallocate)")
    p = tmp_path / "r.h5"
    w = _writer(p)
    w.append(np.ones((100, 2)))
    w.flush()
    st = os.stat(p)
    assert st.st_blocks * 512 - st.st_size > 512 << 10  # a 1 MiB step, the size unchanged by it
    w.close()
    st = os.stat(p)
    assert st.st_blocks * 512 < st.st_size + (64 << 10)
    with h5py.File(p) as f:
        np.testing.assert_array_equal(f["channels/a"][:], np.ones(100))


class _ThirdChannelFails(RunWriter):
    def _write_channel(self, did, x, n0) -> None:
        if n0 and h5py.h5i.get_name(did).endswith(b"/c"):
            did.set_extent((n0 + len(x),))  # extended, then the disk refuses the data
            raise OSError(
                "Can't write data (file write failed: errno = 28, error message = 'No space left')"
            )
        super()._write_channel(did, x, n0)


def test_a_failed_write_leaves_no_channel_claiming_samples_it_lacks(tmp_path):
    p = tmp_path / "r.h5"
    w = _ThirdChannelFails(
        p, rig="test", mode=3, rate_hz=100.0, channels={"a": "V", "b": "V", "c": "V"}, clock=Clock()
    )
    w.append(np.ones((40, 3)))
    w.flush()
    w.append(np.full((25, 3), 2.0))
    with pytest.raises(
        RunFileError, match=r"the disk is full.*Samples 0\.\.40 \(0\.400 s\) were flushed"
    ):
        w.flush()
    w.close("aborted: disk full")
    with h5py.File(p) as f:
        assert [len(f["channels"][c]) for c in "abc"] == [40, 40, 40]  # not 65 with zeros in c
        assert (f["channels/c"][:] == 1.0).all()
