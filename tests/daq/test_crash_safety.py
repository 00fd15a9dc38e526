"""Acceptance A and the full-disk rule: a recording survives SIGKILL, and a write failure puts
the rig in the safe state with a clear error and the flushed samples kept."""

from __future__ import annotations

import resource
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from daq.reader import RunFile
from daq.recorder import record
from daq.recover import recover
from daq.runfile import RunFileError
from drivers.rig import open_rig

pytestmark = pytest.mark.slow
RATE = 1000.0


def _fbs(*args: str, **kw) -> list[str]:
    return [sys.executable, "-m", "fbs.cli", *args]


def test_a_sigkilled_recording_keeps_every_sample_older_than_one_second(tmp_path):
    """A: `fbs record` on the real-time rig is read live (SWMR) and killed with SIGKILL."""
    p = tmp_path / "killed.h5"
    with subprocess.Popen(
        _fbs(
            "record",
            "--rig",
            "sim?realtime=1&warm=1",
            "--mode",
            "3",
            "--duration",
            "120",
            "--rate",
            str(RATE),
            "--channels",
            "gyro_x,gyro_y,ac_x_ctl",
            "--out",
            str(p),
        ),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    ) as proc:
        try:
            seen: list[int] = []
            deadline = time.monotonic() + 90
            start_unix = None
            while time.monotonic() < deadline and (len(seen) < 2 or seen[-1] < 3 * RATE):
                time.sleep(0.2)
                if not p.exists():
                    continue
                try:
                    with RunFile(p) as live:  # a reader while the recording runs
                        if not live.swmr:
                            continue  # not yet streaming
                        start_unix = live.meta["acquisition"]["start_unix_s"]
                        n0 = live.n_samples
                        time.sleep(0.6)
                        live.refresh()  # SWMR: new flushes appear without reopening
                        seen += [n0, live.n_samples]
                except (OSError, KeyError):
                    continue  # created, not yet in SWMR mode
            assert proc.poll() is None, proc.communicate()[1]
            assert len(seen) >= 2 and seen[-1] > seen[-2], f"the live reader saw no growth: {seen}"
            killed_at = time.time()
            proc.send_signal(signal.SIGKILL)
        finally:
            proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    # the paced rig takes sample k no earlier than start_unix + k / RATE, so this many were
    # taken more than one second before the kill
    must_have = int((killed_at - 1.0 - start_unix) * RATE)
    with h5py.File(p, "r", swmr=True) as f:  # plain h5py opens it (SWMR-read mode)
        assert f.attrs["format"] == "fbs-run" and f.attrs["format_version"] == 1
        assert f.attrs["mode"] == 3 and f.attrs["rig"] == "sim?realtime=1&warm=1"
        assert f.attrs["status"] == "recording"
        lengths = {c: len(f["channels"][c]) for c in f["channels"]}
        assert set(lengths) == {"gyro_x", "gyro_y", "ac_x_ctl"}
        assert min(lengths.values()) >= must_have > 1.5 * RATE, (lengths, must_have)
        x = f["channels/gyro_x"][:must_have]
        assert np.isfinite(x).all() and x.std() > 0
        assert f["channels/gyro_x"].attrs["sample_rate_hz"] == RATE
    rec = recover(p)
    with h5py.File(p, "r") as f:  # and with no flags at all after recovery
        assert len(f["channels/gyro_y"]) == rec.samples >= must_have
        assert f.attrs["status"].startswith("aborted: not closed by its writer")
        kinds = [k.decode() for k in f["events"]["kind"]]
        assert kinds[0] == "start"


@pytest.fixture
def file_size_limit():
    """A 'full disk' for this process: files cannot grow past the limit (EFBIG, not SIGXFSZ)."""
    old = resource.getrlimit(resource.RLIMIT_FSIZE)
    old_handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)

    def set_limit(n_bytes: int) -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (n_bytes, old[1]))

    try:
        yield set_limit
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, old)
        signal.signal(signal.SIGXFSZ, old_handler)


def test_a_full_disk_stops_the_recording_safely_and_keeps_what_was_flushed(
    tmp_path, file_size_limit
):
    p = tmp_path / "full.h5"
    with open_rig("sim?warm=1") as rig:
        rig.set_torquer_bias_V("X", 0.5)
        file_size_limit(3 << 20)
        with pytest.raises(RunFileError) as err:
            record(rig, p, duration_s=600.0, rate_hz=RATE, flush_s=0.01)
        file_size_limit(resource.RLIM_INFINITY)
        msg = str(err.value)
        assert (
            f"writing {p} failed (the file size limit was reached)" in msg
            and "were flushed before" in msg
        )
        flushed = int(msg.split("Samples 0..")[1].split(" ")[0])
        nodes = rig.emulator.nodes.nodes
        assert nodes["relay"].mode == 1 and rig.relays.status().mode == 1
        assert not any(nodes["torquer"].values.values()) and not any(
            nodes["command"].values.values()
        )
        assert not rig.adc.streaming
    # the writer's last act failed too, so the file's end is short of its superblock's record
    with pytest.raises(RunFileError, match="fbs recover"):
        RunFile(p)
    rec = recover(p)
    assert rec.samples >= flushed > 0.5 * RATE
    with h5py.File(p) as f:
        assert f.attrs["status"].startswith("aborted: not closed by its writer")
        x = f["channels/gyro_x"][:flushed]
        assert np.isfinite(x).all() and x.std() > 0


def test_an_unwritable_output_fails_before_the_rig_moves(tmp_path):
    (tmp_path / "afile").write_text("not a folder")
    out = tmp_path / "afile" / "r.h5"
    p = subprocess.run(
        _fbs("record", "--mode", "1", "--duration", "1", "--rate", "100", "--out", str(out)),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert (
        p.returncode == 2
        and f"cannot make the run file's folder {out.parent}: it is a file" in p.stderr
    )
    assert "mode" not in p.stdout
    existing = tmp_path / "old.h5"
    existing.write_bytes(b"precious")
    p = subprocess.run(
        _fbs("record", "--mode", "1", "--duration", "1", "--rate", "100", "--out", str(existing)),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert (
        p.returncode == 2
        and "never overwritten" in p.stderr
        and existing.read_bytes() == b"precious"
    )
