"""Real signals to a real ``fbs`` process (issue 19 item 3): SIGINT, SIGTERM and SIGHUP all take
the abort path - rig safe and read back, file closed "aborted: interrupted", exit 2 - also when
the process was started with SIGINT ignored, as a script's background job is."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from daq.reader import RunFile
from tests.fbs.commands import FBS, RIG, SHORT_STOPWATCH

pytestmark = pytest.mark.slow


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _wait_for_samples(p: subprocess.Popen, path, events: int = 0, timeout_s: float = 300.0) -> None:
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end and p.poll() is None:
        time.sleep(0.3)
        try:
            with RunFile(path) as rf:
                if rf.n_samples > 0 and sum(e.kind == "step-done" for e in rf.events) >= events:
                    return
        except (OSError, ValueError):
            pass  # not created or not yet flushed
    raise AssertionError(f"{path} never got going (exit {p.poll()})")


def _signalled(args: list[str], path, sig: signal.Signals, events: int = 0) -> str:
    """Start ``fbs *args`` with SIGINT ignored, send ``sig`` once ``path`` has samples (and
    ``events`` steps done), and return its stderr once it has exited 2 with the file
    "aborted: interrupted" and the rig's "safe state reached" event."""
    with subprocess.Popen(
        [*FBS, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
        preexec_fn=_ignore_sigint,
    ) as p:
        try:
            _wait_for_samples(p, path, events)
            p.send_signal(sig)
            _, stderr = p.communicate(timeout=120)
        finally:
            p.kill()
    assert p.returncode == 2, stderr
    with RunFile(path) as rf:
        assert rf.status == "aborted: interrupted"
        assert any(e.kind == "safe" and e.text == "safe state reached" for e in rf.events), stderr
    return stderr


@pytest.mark.parametrize(
    "sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=lambda s: s.name
)
def test_a_signal_aborts_a_recording_to_the_safe_state(tmp_path, sig):
    path = tmp_path / "r.h5"
    err = _signalled(
        [
            "record",
            "--rig",
            "sim",
            "--mode",
            "3",
            "--duration",
            "100000",
            "--rate",
            "100",
            "--out",
            str(path),
        ],
        path,
        sig,
    )
    assert f"fbs record: interrupted ({sig.name})" in err, err  # the signal that came (issue 37)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=lambda s: s.name)
def test_a_signal_aborts_a_procedure_to_the_safe_state_naming_it(tmp_path, sig):
    """Issue 37 item 10: after SIGTERM ``fbs run`` said "interrupted (Ctrl-C)"."""
    err = _signalled(
        ["run", "stopwatch", "--rig", "sim?warm=1", "--out", str(tmp_path)],
        tmp_path / "stopwatch.h5",
        sig,
        events=1,
    )
    assert f"fbs run stopwatch: interrupted ({sig.name})" in err and "Ctrl-C" not in err, err
    summary = json.loads((tmp_path / "stopwatch.json").read_text())
    assert summary["error"] == f"interrupted ({sig.name})", summary


def test_a_signal_while_the_program_starts_exits_2_without_a_traceback(tmp_path):
    """Issue 36 item 11: Ctrl-C while ``fbs`` was still loading printed a KeyboardInterrupt
    traceback; SIGTERM/SIGHUP there ended it with 143/129. The signal is sent once the child
    has its start-up handler (its caught-signal mask has SIGTERM), while it is loading."""
    import re as _re

    with subprocess.Popen(
        [
            sys.executable,
            "-m",
            "fbs",
            "simulate",
            "--mode",
            "3",
            "--duration",
            "1",
            "--rate",
            "100",
            "--out",
            str(tmp_path / "x.h5"),
        ],
        stderr=subprocess.PIPE,
        text=True,
    ) as proc:
        try:
            status = Path(f"/proc/{proc.pid}/status")
            t_end = time.monotonic() + 60  # a hang guard
            while proc.poll() is None and time.monotonic() < t_end:
                m = _re.search(r"^SigCgt:\s*([0-9a-f]+)", status.read_text(), _re.M)
                if m and int(m.group(1), 16) >> (signal.SIGTERM - 1) & 1:
                    break
                time.sleep(0.001)  # not a core spent spinning while the child starts
            proc.send_signal(signal.SIGTERM)
            _, err = proc.communicate(timeout=120)
        finally:
            proc.kill()  # a failure above must not leave it running
    assert proc.returncode == 2 and "Traceback" not in err, err
    assert "SIGTERM while starting; nothing was done" in err or "interrupted" in err, err


SW_RIG = ["--rig", RIG]


def _main_thread_waits(pid: int, quiet_s: float = 0.5) -> bool:
    """The process's main thread sleeps in the kernel (a FIFO's open) and stays so ``quiet_s``."""
    t_end = time.monotonic() + quiet_s
    while time.monotonic() < t_end:
        try:
            if "wait_for_partner" in Path(f"/proc/{pid}/wchan").read_text():
                return True  # the kernel names it: blocked opening a FIFO
        except OSError:
            pass  # not shown here: the thread's state alone
        try:
            stat = Path(f"/proc/{pid}/task/{pid}/stat").read_text()
            if stat.rsplit(")", 1)[1].split()[0] != "S":
                return False
        except OSError:
            return False
        time.sleep(0.05)
    return True


def test_sighup_while_the_report_is_written_then_resume_writes_it(tmp_path):
    """Issue 36 item 11: SIGHUP while stopwatch wrote its report left exit 2, a summary saying
    pass/complete, no report, and ``--resume`` refused the complete file. The report's temporary
    name (``procedures.reports.textfile``: ``.stopwatch.md.PID.tmp``) is made a FIFO before the
    run reaches it: the run, its acquisition and analysis done and its plot drawn, waits opening
    it, in the report, until SIGHUP comes. Then exit 2 and a summary saying so; ``--resume``
    analyses the complete file again, writing the report and a true summary."""
    with subprocess.Popen(
        [*FBS, "run", "stopwatch", "--out", str(tmp_path), *SW_RIG, *SHORT_STOPWATCH],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    ) as p:
        fifo = tmp_path / f".stopwatch.md.{p.pid}.tmp"
        os.mkfifo(fifo)  # before the child has even loaded (seconds)
        try:
            t_end = time.monotonic() + 300  # a hang guard
            while not (list(tmp_path.glob("stopwatch-*.png")) and _main_thread_waits(p.pid)):
                assert p.poll() is None and time.monotonic() < t_end, p.communicate()
                time.sleep(0.1)
            p.send_signal(signal.SIGHUP)
            _, stderr = p.communicate(timeout=120)
        finally:
            p.kill()
    assert p.returncode == 2, stderr
    assert not fifo.exists() and not (tmp_path / "stopwatch.md").exists(), stderr
    summary = json.loads((tmp_path / "stopwatch.json").read_text())
    assert summary["verdict"] == "aborted" and summary["report"] is None, summary
    assert "interrupted while the report was written" in summary["error"]
    assert "no report" in summary["error"]
    with RunFile(tmp_path / "stopwatch.h5") as rf:
        assert rf.status == "complete"
    r = subprocess.run(
        [
            *FBS,
            "run",
            "stopwatch",
            *SW_RIG,
            "--out",
            str(tmp_path),
            "--json",
            "--resume",
            str(tmp_path / "stopwatch.h5"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 1, r.stderr  # complete; one repetition resolves no K_g (issue 37)
    assert json.loads(r.stdout)["file"] == str(tmp_path / "stopwatch.h5")
    summary = json.loads((tmp_path / "stopwatch.json").read_text())
    assert summary["verdict"] == "fail" and summary["status"] == "complete"
    assert summary["error"] is None and summary["report"] == str(tmp_path / "stopwatch.md")
    assert "**fail**" in (tmp_path / "stopwatch.md").read_text()
    assert [f.name for f in tmp_path.glob("*.h5")] == ["stopwatch.h5"]  # nothing recorded again
    assert "analysing it again" in (tmp_path / "stopwatch.log").read_text()  # the run's own log
