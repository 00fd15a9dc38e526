"""Issue 7, acceptance B: ``fbs console`` in a real terminal (tmux, 80x24) shows the meter
panel within 3 s, and quits cleanly on its quit key, leaving no process behind.

The start time is printed (``-s`` shows it); the test asserts the behaviour, with a generous
time-out on a loaded machine rather than the 3 s, which is a figure to report, not to assert
(DESIGN: tests never assert timing).
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from drivers.logrule import PROJECT_PACKAGES as PROJECT

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        shutil.which("tmux") is None,
        reason="tmux is not installed: acceptance B needs a real terminal multiplexer",
    ),
]

FBS = Path(sys.executable).with_name("fbs")
#: a guard against a hang, not a deadline
HANG_S = 120.0


def tmux(*args: str) -> str:
    return subprocess.run(["tmux", *args], check=True, capture_output=True, text=True).stdout


def capture(session: str) -> str:
    return tmux("capture-pane", "-p", "-t", session)


def descendants(pid: int) -> list[int]:
    """Every live process below ``pid`` (from /proc, no psutil)."""
    children: dict[int, list[int]] = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(d.name))
    out, todo = [], [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.append(c)
            todo.append(c)
    return out


def alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def test_fbs_console_in_tmux_shows_meters_and_quits_cleanly(tmp_path):
    assert FBS.exists(), f"{FBS} not installed (pip install -e .)"
    session = f"fbs-console-{uuid.uuid4().hex[:8]}"
    out = tmp_path / "out"
    cmd = f"cd {tmp_path} && exec {FBS} console --out {out}"  # the default rig: sim?realtime=1
    t0 = time.monotonic()
    tmux("new-session", "-d", "-s", session, "-x", "80", "-y", "24", cmd)
    try:
        pane_pid = int(tmux("display-message", "-p", "-t", session, "#{pane_pid}").strip())
        screen, shown_s = "", None
        while time.monotonic() - t0 < 30:
            screen = capture(session)
            if "torq_xrd" in screen and "urad/s" in screen and "ac_y_ctl" in screen:
                shown_s = time.monotonic() - t0
                break
            time.sleep(0.05)
        assert shown_s is not None, f"no meter panel after 30 s:\n{screen}"
        # the readings arrive from the rig thread: digits replace the dashes
        t_end = time.monotonic() + 20
        while (
            "—" in capture(session).split("torq_x ", 1)[1].split("\n", 1)[0]
            and time.monotonic() < t_end
        ):
            time.sleep(0.1)
        assert "MODE 1" in capture(session)
        print(
            f"\nfbs console: meter panel shown {shown_s:.2f} s after start (acceptance: within 3 s)"
        )
        procs = [pane_pid, *descendants(pane_pid)]
        tmux("send-keys", "-t", session, "q")
        t_end = time.monotonic() + 30
        while any(alive(p) for p in procs) and time.monotonic() < t_end:
            time.sleep(0.1)
        left = [p for p in procs if alive(p)]
        assert not left, f"processes left behind after quit: {left}"
        print(f"fbs console: quit, no process left ({time.monotonic() - t0:.1f} s in all)")
    finally:
        subprocess.run(["tmux", "kill-session", "-t", session], capture_output=True)
    log = (out / "console.log").read_text()
    assert "safe state: yes (read back)" in log


def test_killing_the_tmux_session_while_recording_ends_the_console_safely(tmp_path):
    """Issue 35 F / acceptance D: the console outlived its terminal (its main thread blocked on
    the dead screen, SIGTERM ignored). Killing its tmux session mid-recording now ends the
    process, the file closed "aborted: <why>", the rig safe, read back. The time to exit is
    printed (the issue asks for 10 s); the test asserts the outcome behind a hang guard."""
    session = f"fbs-console-{uuid.uuid4().hex[:8]}"
    out = tmp_path / "out"
    cmd = f"cd {tmp_path} && exec {FBS} console --out {out}"
    tmux("new-session", "-d", "-s", session, "-x", "80", "-y", "24", cmd)
    try:
        pane_pid = int(tmux("display-message", "-p", "-t", session, "#{pane_pid}").strip())
        t_end = time.monotonic() + HANG_S
        while "torq_xrd" not in capture(session) and time.monotonic() < t_end:
            time.sleep(0.1)
        tmux("send-keys", "-t", session, "F4")
        while (
            " open (" not in capture(session) and time.monotonic() < t_end
        ):  # the event log: rig open
            time.sleep(0.1)
        tmux("send-keys", "-t", session, "F7")  # record, with the panel's defaults
        while not list(out.glob("*.h5")) and time.monotonic() < t_end:
            time.sleep(0.1)
        files = list(out.glob("*.h5"))
        assert files, f"no recording started:\n{capture(session)}"
        time.sleep(1.0)  # a second of samples
        procs = [pane_pid, *descendants(pane_pid)]
        t_kill = time.monotonic()
        subprocess.run(["tmux", "kill-session", "-t", session], check=True)
        while any(alive(p) for p in procs) and time.monotonic() - t_kill < HANG_S:
            time.sleep(0.1)
        left = [p for p in procs if alive(p)]
        assert not left, f"the console outlived its terminal: {left}"
        print(
            f"\nfbs console: gone {time.monotonic() - t_kill:.1f} s after its tmux session was killed "
            f"(issue 35 asks for 10 s)"
        )
    finally:
        subprocess.run(["tmux", "kill-session", "-t", session], capture_output=True)
    from daq.reader import RunFile

    with RunFile(files[0]) as rf:
        assert rf.status.startswith("aborted: ") and (
            "SIGHUP" in rf.status or "terminal" in rf.status
        ), rf.status
    log = (out / "console.log").read_text()
    assert "safe state reached" in log or "safe state: yes (read back)" in log, log[-2000:]


def test_sighup_ends_the_console_with_exit_2_and_its_log_is_this_programs(tmp_path):
    """Issue 37 items 5 and 10: the console exited 0 after SIGHUP (it must say "aborted": 2),
    and its log was 98 % the CANopen stack's INFO lines. The console runs under a small parent
    that records its exit code; SIGHUP goes to the console alone, once its meters show readings."""
    session = f"fbs-console-{uuid.uuid4().hex[:8]}"
    out, rc = tmp_path / "out", tmp_path / "rc"
    parent = (
        f"import subprocess; r = subprocess.call([{str(FBS)!r}, 'console', '--out', "
        f"{str(out)!r}]); open({str(rc)!r}, 'w').write(str(r))"
    )
    tmux(
        "new-session",
        "-d",
        "-s",
        session,
        "-x",
        "80",
        "-y",
        "24",
        f'cd {tmp_path} && exec {sys.executable} -c "{parent}"',
    )
    try:
        pane_pid = int(tmux("display-message", "-p", "-t", session, "#{pane_pid}").strip())
        t_end = time.monotonic() + HANG_S
        while "torq_xrd" not in capture(session) and time.monotonic() < t_end:
            time.sleep(0.1)
        # readings (digits, not dashes): the rig's nodes answered, canopen has logged
        while (
            "—" in capture(session).split("torq_x ", 1)[-1].split("\n", 1)[0]
            and time.monotonic() < t_end
        ):
            time.sleep(0.1)
        # the console, not its parent (whose code mentions 'console' inside one argument)
        console = [
            p
            for p in descendants(pane_pid)
            if b"console" in Path(f"/proc/{p}/cmdline").read_bytes().split(b"\0")
        ]
        assert console, f"no console process:\n{capture(session)}"
        subprocess.run(["kill", "-HUP", str(console[0])], check=True)
        while not rc.exists() and time.monotonic() < t_end:
            time.sleep(0.1)
        assert rc.exists(), f"the console did not end after SIGHUP:\n{capture(session)}"
    finally:
        subprocess.run(["tmux", "kill-session", "-t", session], capture_output=True)
    assert rc.read_text() == "2"
    lines = (out / "console.log").read_text().splitlines()
    assert any(" INFO drivers.rig: " in ln for ln in lines), lines[:20]  # this program's INFO
    records = [m for m in (re.match(r"\S+ \S+ (INFO|DEBUG) ([\w.]+): ", ln) for ln in lines) if m]
    others = {m.group(2) for m in records if m.group(2).split(".")[0] not in PROJECT}
    assert not others, others  # no other library's INFO (canopen's)
    stamp = r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\.\d{3}[+-]\d{4} "  # with its UTC offset
    assert re.match(stamp, lines[0]), lines[0]
