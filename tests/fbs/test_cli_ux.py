"""A command line scripts can trust (issue 20, acceptance C and D), through real ``fbs``
processes: ``--version``; ``fbs run NAME --help`` with the procedure's parameters; usage errors
exit 64, bad values and aborts 2; ``--json`` prints one object on simulate, record, inspect and
recover; on a terminal (a real pseudo-terminal) ``fbs run`` keeps one status line updated in
place, elsewhere it writes plain timestamped progress lines at a modest rate; ``<run>.log``
beside each run file; ``-v`` is this project's loggers only."""

from __future__ import annotations

import fcntl
import json
import os
import re
import select
import signal
import struct
import subprocess
import sys
import termios
import textwrap
import time
from pathlib import Path

import pytest

from fbs.usage import EXIT_USAGE
from tests.fbs.commands import FBS, RIG, SHORT_STOPWATCH

ROOT = Path(__file__).parents[2]
#: the machine running the suite may be heavily loaded: generous, never asserted as timing
TIMEOUT_S = 600
STAMP = r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\.\d{3}[+-]\d{4}"  # local time, its UTC offset
LOG_LINE = re.compile(rf"^{STAMP} (DEBUG|INFO|WARNING|ERROR|CRITICAL) [\w.]+: ")
#: the status line as drawn: its bar, then the procedure's progress
STATUS = re.compile(r"\[[#-]{12}\] stopwatch: +\d+ %, step \d/\d ")
PROJECT = ("fbs", "drivers", "simhw", "daq", "procedures", "console")


def fbs(*args: str, timeout: float = TIMEOUT_S) -> subprocess.CompletedProcess:
    return subprocess.run([*FBS, *args], capture_output=True, text=True, timeout=timeout, cwd=ROOT)


# ---------------------------------------------------------------------------- C: version, help, exit codes
def test_version():
    r = fbs("--version")
    assert r.returncode == 0 and re.fullmatch(r"fbs-hil \S+\n", r.stdout), r


def test_help_states_the_exit_codes_and_imports_no_procedure():
    code = textwrap.dedent("""
        import sys
        from fbs.cli import main
        try:
            main(["--help"])
        except SystemExit as exc:
            print("exit", exc.code)
        print("imported:", sorted(m for m in sys.modules if m.startswith("procedures.calibrations.")))
    """)
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=TIMEOUT_S, cwd=ROOT
    )
    assert "exit 0" in r.stdout and "imported: []" in r.stdout, r.stdout + r.stderr
    assert "exit codes:" in r.stdout and f"{EXIT_USAGE}  usage error" in r.stdout
    assert "DESIGN" not in r.stdout


def test_run_name_help_lists_the_procedures_parameters_with_defaults_units_and_limits():
    r = fbs("run", "stopwatch", "--help")
    assert r.returncode == 0, r.stderr
    out = r.stdout
    assert "usage: fbs run" in out and "parameters of stopwatch" in out
    assert re.search(r"^  repetitions = 3  \(integer, limits: 1\.\.4\)$", out, re.M), out
    assert re.search(r"^  hold_s = 20\.0  \(number, s, limits: > 0\)$", out, re.M), out
    assert re.search(
        r"^  ramp_rate_urad_per_s = 20\.0  \(number, urad/s, limits: 0\.1\.\.100\)$", out, re.M
    ), out
    assert re.search(
        r"^  delta_pickoff_V = 2\.0  \(number, V, limits: 0\.05\.\.8 V\)$", out, re.M
    ), out
    # a limit that is no range is stated too: the channels to choose from
    assert re.search(
        r"^  channels = \[.*\]  \(list of text, limits: non-empty, each one of X, Y, Z, XRD\)$",
        out,
        re.M,
    ), out
    assert "a repetition is a ramp down and a ramp up" in out  # what it is for
    assert "DESIGN" not in out
    # without a name: the command's own help, no procedure's parameters
    r = fbs("run", "--help")
    assert r.returncode == 0 and "parameters of" not in r.stdout and "PROCEDURE --help" in r.stdout


@pytest.mark.parametrize(
    "argv",
    [
        ["frobnicate"],  # unknown command
        [],  # no command
        ["inspect"],  # missing argument
        ["inspect", "x.h5", "--bogus"],  # unknown flag
        ["analyze"],  # missing sub-command
        ["run", "no-such-procedure"],  # unknown procedure
        [
            "simulate",
            "--mode",
            "3",
            "--duration",
            "ten",
            "--rate",
            "100",
            "--out",
            "x.h5",
        ],  # type error
        [
            "simulate",
            "--mode",
            "9",
            "--duration",
            "1",
            "--rate",
            "100",
            "--out",
            "x.h5",
        ],  # not a choice
    ],
    ids=lambda a: " ".join(a) or "none",
)
def test_a_usage_error_exits_with_the_usage_code(tmp_path, argv):
    r = subprocess.run(
        [*FBS, *argv], capture_output=True, text=True, timeout=TIMEOUT_S, cwd=tmp_path
    )
    assert r.returncode == EXIT_USAGE == 64, r
    assert r.stderr.startswith("usage: fbs") and "error:" in r.stderr and r.stdout == ""
    assert not list(tmp_path.iterdir())  # nothing started


def test_a_bad_value_stays_exit_2_naming_it(tmp_path):
    r = fbs(
        "simulate",
        "--mode",
        "3",
        "--duration",
        "nan",
        "--rate",
        "100",
        "--out",
        str(tmp_path / "x.h5"),
    )
    assert r.returncode == 2 and "--duration nan must be a finite number > 0" in r.stderr
    r = fbs("run", "stopwatch", "--out", str(tmp_path), "--param", "repetitions=51")
    assert r.returncode == 2 and "repetitions = 51 must be 1..4" in r.stderr
    assert not list(tmp_path.iterdir())  # no run file, no log


# ---------------------------------------------------------------------------- C: --json, one object
def _one_object(r: subprocess.CompletedProcess) -> dict:
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert len(lines) == 1, r.stdout
    obj = json.loads(lines[0])
    assert isinstance(obj, dict)
    return obj


def test_json_on_simulate_inspect_record_and_recover(tmp_path):
    sim = tmp_path / "s.h5"
    o = _one_object(
        fbs(
            "simulate",
            "--mode",
            "3",
            "--duration",
            "4",
            "--rate",
            "50",
            "--seed",
            "2",
            "--effect",
            "pickup_line:freq_hz=10,amplitude_V=0.003",
            "--out",
            str(sim),
            "--json",
        )
    )
    assert (
        o["file"] == str(sim)
        and o["n_samples"] == 200
        and o["rate_hz"] == 50.0
        and o["duration_s"] == 4.0
    )
    assert o["status"] == "complete" and o["mode"] == 3 and o["seed"] == 2
    assert (
        o["effects"] == ["pickup_line:freq_hz=10,amplitude_V=0.003"]
        and o["channels"]["gyro_x"] == "V"
    )

    o = _one_object(fbs("inspect", str(sim), "--json"))
    assert o["file"] == str(sim) and o["n_samples"] == 200 and o["status"] == "complete"

    rec = tmp_path / "r.h5"
    o = _one_object(
        fbs(
            "record",
            "--rig",
            "sim?warm=1",
            "--mode",
            "3",
            "--duration",
            "2",
            "--rate",
            "100",
            "--channels",
            "gyro_x,ac_x_ctl",
            "--out",
            str(rec),
            "--json",
        )
    )
    assert (
        o["file"] == str(rec)
        and o["n_samples"] == 200
        and sorted(o["channels"]) == ["ac_x_ctl", "gyro_x"]
    )
    assert o["status"] == "complete" and o["lost"] == 0 and o["gaps"] == []

    killed = tmp_path / "k.h5"  # a writer killed mid-recording
    script = textwrap.dedent("""
        import os, signal, sys
        import numpy as np
        from daq.runfile import RunWriter
        w = RunWriter(sys.argv[1], rig="t", mode=1, rate_hz=10.0, channels={"a": "V"})
        w.append(np.ones((40, 1)))
        w.flush()
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    assert (
        subprocess.run(
            [sys.executable, "-c", script, str(killed)], timeout=TIMEOUT_S, cwd=ROOT
        ).returncode
        == -9
    )
    o = _one_object(fbs("recover", str(killed), "--json"))
    assert o["was_open"] is True and o["n_samples"] == 40 and o["duration_s"] == 4.0
    o = _one_object(fbs("recover", str(sim), "--json"))
    assert o["was_open"] is False and o["status"] == "complete"


# ---------------------------------------------------------------------------- D: progress and the run's log
def _run_on_a_pty(argv: list[str], columns: int = 100) -> tuple[int, str]:
    """``fbs argv`` with stdout and stderr on a real pseudo-terminal of ``columns`` columns:
    (exit code, everything it wrote to the terminal)."""
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 30, columns, 0, 0))
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")} | {"TERM": "xterm"}
    with subprocess.Popen(
        [*FBS, *argv], stdin=subprocess.DEVNULL, stdout=slave, stderr=slave, cwd=ROOT, env=env
    ) as p:
        os.close(slave)
        out = b""
        t_end = time.monotonic() + TIMEOUT_S
        try:
            while time.monotonic() < t_end:
                ready, _, _ = select.select([master], [], [], 1.0)
                if ready:
                    try:
                        chunk = os.read(master, 65536)
                    except OSError:  # EIO: every holder of the terminal's slave side has gone
                        break
                    if not chunk:
                        break
                    out += chunk
                elif p.poll() is not None:
                    break
            code = p.wait(timeout=60)
        finally:
            p.kill()
            os.close(master)
    return code, out.decode("utf-8", "replace")


def _screen_lines(raw: str) -> list[str]:
    """The lines a terminal is left with after ``raw`` (carriage return, "erase to end of
    line" and newline interpreted; nothing else is expected)."""
    lines, line, col = [], [], 0
    for token in re.findall(r"\x1b\[K|\r\n|\r|\n|[^\r\n\x1b]|\x1b", raw):
        if token == "\x1b[K":
            del line[col:]
        elif token in ("\r\n", "\n"):
            lines.append("".join(line))
            line, col = [], 0
        elif token == "\r":
            col = 0
        else:
            if col < len(line):
                line[col] = token
            else:
                line.append(token)
            col += 1
    if line:
        lines.append("".join(line))
    return lines


def test_a_terminal_shows_one_updating_progress_line_and_the_log_lands_beside_the_run(tmp_path):
    code, raw = _run_on_a_pty(
        ["run", "stopwatch", "--rig", RIG, "--out", str(tmp_path), *SHORT_STOPWATCH]
    )
    assert code == 1, raw  # one repetition resolves no K_g: no pass (issue 37), a complete run
    # the status line was drawn several times (each step at least), always from column 0 ...
    draws = [m.start() for m in STATUS.finditer(raw)]
    assert len(draws) >= 2, raw
    assert all(raw[i - 1] == "\r" for i in draws), raw
    assert len(set(re.findall(r"\d+ %, step \d/\d [^;]*", raw))) >= 2, (
        raw
    )  # and said different things
    # ... and never left as a line of its own: the terminal holds the log records and the
    # result, one line each, and no status line (it is erased when the run ends)
    screen = _screen_lines(raw)
    assert not [ln for ln in screen if STATUS.search(ln)], screen
    assert any(ln.startswith("fbs run stopwatch: fail (complete)") for ln in screen), screen
    records = [ln for ln in screen if LOG_LINE.match(ln)]
    assert records and not [ln for ln in records if " fbs.run_progress: " in ln], (
        screen
    )  # the line, not lines

    log = (tmp_path / "stopwatch.log").read_text()
    lines = log.splitlines()
    assert lines and all(LOG_LINE.match(ln) for ln in lines), log
    assert "\x1b" not in log and "\r" not in log
    assert re.search(
        r" INFO fbs\.run: fbs run stopwatch --rig .* \(fbs-hil \S+, pid \d+ on ", lines[0]
    ), lines[0]
    assert any(" fbs.run_progress: stopwatch: " in ln and "step 2/2" in ln for ln in lines), log
    assert any(" drivers.rig: rig sim?warm=1" in ln and " open: " in ln for ln in lines), (
        log
    )  # held, then written
    assert "fbs run stopwatch: fail (complete)" in lines[-1], log


def test_not_a_terminal_plain_progress_lines_at_a_modest_rate_verbose_only_for_this_project(
    tmp_path,
):
    first = fbs("run", "stopwatch", "--rig", RIG, "--out", str(tmp_path), *SHORT_STOPWATCH)
    assert first.returncode == 1, first.stderr  # complete; one repetition is no pass (issue 37)
    first_log = (tmp_path / "stopwatch.log").read_text()
    r = fbs(
        "-v", "run", "stopwatch", "--rig", RIG, "--out", str(tmp_path), "--json", *SHORT_STOPWATCH
    )
    assert r.returncode == 1, r.stderr
    assert json.loads(r.stdout)["file"] == str(tmp_path / "stopwatch-2.h5")
    # the second run's log is beside its own file; the first run's is untouched
    assert (tmp_path / "stopwatch-2.log").exists() and (
        tmp_path / "stopwatch.log"
    ).read_text() == first_log

    for stderr in (first.stderr, r.stderr):
        assert "\r" not in stderr and "\x1b" not in stderr
        lines = stderr.splitlines()
        assert lines and all(LOG_LINE.match(ln) for ln in lines), stderr
        progress = [ln for ln in lines if " fbs.run_progress: stopwatch: " in ln]
        # each step, each tenth of the run, the end: a handful, where the runner reports hundreds
        assert 2 <= len(progress) <= 2 + 11 + 1, progress
    debug = [ln for ln in r.stderr.splitlines() if " DEBUG " in ln]
    assert debug, r.stderr
    loggers = {re.match(rf"{STAMP} DEBUG ([\w.]+):", ln).group(1) for ln in debug}  # type: ignore[union-attr]
    assert all(name.split(".")[0] in PROJECT for name in loggers), (
        loggers
    )  # no matplotlib font manager
    assert not [ln for ln in first.stderr.splitlines() if " DEBUG " in ln]
    log2 = (tmp_path / "stopwatch-2.log").read_text()
    assert " DEBUG drivers." in log2 and all(LOG_LINE.match(ln) for ln in log2.splitlines())


def test_an_aborted_run_exits_2_and_its_log_says_so(tmp_path):
    """Ctrl-C (SIGINT) once the run is under way: exit 2, file aborted, the log ends with it."""
    with subprocess.Popen(
        [*FBS, "run", "stopwatch", "--rig", RIG, "--out", str(tmp_path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    ) as p:
        log = tmp_path / "stopwatch.log"
        t_end = time.monotonic() + TIMEOUT_S
        try:
            while time.monotonic() < t_end and p.poll() is None:
                if log.exists() and " fbs.run_progress: stopwatch: " in log.read_text():
                    break
                time.sleep(0.2)
            assert p.poll() is None, p.communicate()
            p.send_signal(signal.SIGINT)
            out, err = p.communicate(timeout=TIMEOUT_S)
        finally:
            p.kill()
    assert p.returncode == 2, err
    assert "fbs run stopwatch: aborted (aborted: interrupted)" in out
    text = log.read_text()
    assert all(LOG_LINE.match(ln) for ln in text.splitlines()), text
    assert (
        "stopwatch aborted in step" in text
        and "fbs run stopwatch: aborted (aborted: interrupted)" in text
    )
