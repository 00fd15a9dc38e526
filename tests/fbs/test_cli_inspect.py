"""`fbs inspect` and `fbs recover` on closed, foreign and killed-writer files."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import h5py
import numpy as np

from daq.runfile import RunWriter
from fbs.cli import main


def test_inspect_prints_channels_units_rate_duration_status_and_events(tmp_path, capsys):
    p = tmp_path / "r.h5"
    with RunWriter(
        p,
        rig="sim?warm=1",
        mode=3,
        rate_hz=200.0,
        channels={"gyro_x": "V", "theta_x": "rad"},
        axis="X",
        procedure="survey",
    ) as w:
        w.append(np.zeros((1000, 2)))
        w.event(0.0, "mode", "mode 3")
        w.event(2.5, "gap", "ADC samples 500..509 lost (missing frame)")
    assert main(["inspect", str(p)]) == 0
    out = capsys.readouterr().out
    assert "fbs-run version 1" in out and "rig sim?warm=1, mode 3, axis X, procedure survey" in out
    assert "status: complete" in out and "rate 200 Hz, 1000 samples, duration 5.000 s" in out
    assert "gyro_x   V" in out and "theta_x  rad" in out
    assert "events (2):" in out and "2.5000 s  gap" in out and "ADC samples 500..509 lost" in out
    assert "SWMR" not in out


def test_inspect_names_a_bad_file_and_exits_2(tmp_path, capsys):
    with h5py.File(tmp_path / "x.h5", "w") as f:
        f.attrs["format"] = "other"
    assert main(["inspect", str(tmp_path / "x.h5")]) == 2
    assert "is not an fbs-run file (format = 'other')" in capsys.readouterr().err
    assert main(["inspect", str(tmp_path / "nope.h5")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_a_killed_writers_file_is_inspected_then_recovered(tmp_path, capsys):
    p = tmp_path / "k.h5"
    script = textwrap.dedent("""
        import os, signal, sys
        import numpy as np
        from daq.runfile import RunWriter
        w = RunWriter(sys.argv[1], rig="t", mode=1, rate_hz=10.0, channels={"a": "V"})
        w.append(np.ones((40, 1)))
        w.flush()
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    assert subprocess.run([sys.executable, "-c", script, str(p)], timeout=60).returncode == -9
    assert main(["inspect", str(p)]) == 0
    out = capsys.readouterr().out
    assert "status: aborted: the writer died without closing the file" in out
    assert "(gone)" in out and "opened in SWMR mode" in out and "40 samples" in out
    assert main(["recover", str(p)]) == 0
    assert "recovered; 40 samples per channel (4.000 s) kept" in capsys.readouterr().out
    assert main(["inspect", str(p)]) == 0
    out = capsys.readouterr().out
    assert "SWMR" not in out and "status: aborted: not closed by its writer" in out


def test_json_is_strict_where_a_file_holds_a_time_that_is_no_number(tmp_path, capsys):
    """A file written by another system may carry an event at time NaN (a clock not yet set):
    ``--json`` printed Python's bare ``NaN`` token, which RFC 8259 refuses (jq, a browser and
    strict parsers reject the whole object). Every command's JSON now says null there
    (``fbs.jsonout``)."""
    import json

    p = tmp_path / "r.h5"
    with RunWriter(p, rig="other", mode=3, rate_hz=200.0, channels={"gyro_x": "V"}) as w:
        w.append(np.zeros((100, 1)))
        w.event(float("nan"), "note", "clock not set")
    assert main(["inspect", str(p), "--json"]) == 0
    text = capsys.readouterr().out

    def refuse(token: str) -> None:
        raise ValueError(f"not JSON: {token}")

    out = json.loads(text, parse_constant=refuse)
    assert [e["time_s"] for e in out["events"]] == [None]
