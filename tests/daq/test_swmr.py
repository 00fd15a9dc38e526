"""A SWMR reader gives up on damaged metadata in about a second instead of HDF5's hour of
retries (``fbs inspect`` and ``fbs recover`` hung on such a file), and still reads a live file."""

from __future__ import annotations

import shutil
import subprocess
import sys

import numpy as np

from daq.runfile import RunWriter
from daq.swmr import open_swmr_read


def _live_copy(tmp_path):
    """A live writer's file, and a byte copy of it: what a killed writer leaves."""
    w = RunWriter(
        tmp_path / "live.h5", rig="t", mode=3, rate_hz=100.0, channels={"a": "V", "b": "V"}
    )
    w.append(np.ones((500, 2)))
    w.flush()
    shutil.copyfile(w.path, tmp_path / "killed.h5")
    return w, tmp_path / "killed.h5"


def test_a_live_file_reads_and_damaged_metadata_fails_fast(tmp_path):
    w, killed = _live_copy(tmp_path)
    try:
        with open_swmr_read(w.path) as f:
            assert f["channels/a"].shape == (500,) and f.attrs["status"] == "recording"
    finally:
        w.close()
    raw = bytearray(killed.read_bytes())
    root = int.from_bytes(raw[raw.index(b"\x89HDF\r\n\x1a\n") + 36 :][:8], "little")
    assert raw[root : root + 4] == b"OHDR"
    raw[root + 8 : root + 24] = bytes(16)
    killed.write_bytes(bytes(raw))
    # in a child, so that a hang (the old behaviour) fails the test instead of blocking it
    code = (
        "import sys\nfrom daq.swmr import open_swmr_read\n"
        "try:\n    open_swmr_read(sys.argv[1]).attrs['status']\nexcept (KeyError, OSError) as e:\n"
        "    print('refused:', e)\n"
    )
    p = subprocess.run(
        [sys.executable, "-c", code, str(killed)], capture_output=True, text=True, timeout=120
    )
    assert p.returncode == 0 and "refused:" in p.stdout and "checksum" in p.stdout, p.stderr
