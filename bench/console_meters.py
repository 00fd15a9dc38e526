"""The console while recording: meter refresh rate and the console process's CPU (issue 7, C).

The acceptance point: while recording 16 channels at 1 kHz, the meters refresh at least 10
times a second and the console process uses less than half a core.

How it is measured, all in this run:

* The console is the real one (``console.app.ConsoleApp`` with Textual's real terminal
  driver) in a child process whose terminal is a pseudo-terminal of 80x24 (``TERM`` xterm-
  256color); this process drains the terminal's output as a terminal emulator would. The
  rig is the paced simulated rig, ``sim?realtime=1`` (the console's default), which runs in
  the console's own process: its physics, the ADC's pty and the CAN nodes are part of the
  CPU figure, as they would not be with hardware. Once the rig is open the child starts a
  recording of 16 channels (section 5 less the command inputs) at 1 kHz through the
  console's rig thread, lets it run ``--warmup`` s (5), then measures for ``--seconds`` (20):
  the meter table's paints (``MeterTable.render`` calls: a paint is a redraw on the
  terminal) per second of wall time, and the process's CPU time (``getrusage``, every
  thread) per second of wall time, as a fraction of one core; the parent reads
  ``/proc/<pid>/stat`` over the same span as a cross-check. Then the recording is stopped
  (status must be "complete", no gaps) and the console quits.
* The baseline, in the same run: the same rig recording the same 16 channels at 1 kHz for the
  same time with no console (``daq.recorder.record`` in a child process), its CPU fraction
  measured the same way. Console minus baseline is what the console itself costs (the UI,
  its rig thread, the meter tap).
* Targets: refresh >= 10 Hz, CPU < 0.5 core; printed as ratios (refresh / 10 Hz, 0.5 core /
  CPU: above 1 meets the target).

Benchmarks report, they never fail: the exit code is 0 and a missed target prints a
``TARGET MISSED`` line. Usage: ``python bench/console_meters.py [--quick] [--seconds S]``.
"""

from __future__ import annotations

import argparse
import fcntl
import json
import os
import pty
import struct
import subprocess
import sys
import tempfile
import termios
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
CHILD = HERE / "_console_child.py"
TARGET_HZ = 10.0
TARGET_CORE = 0.5
COLS, ROWS = 80, 24


def log(msg: str = "") -> None:
    print(msg, flush=True)


def proc_cpu_s(pid: int) -> float | None:
    """utime + stime of ``pid`` (all threads) from /proc/<pid>/stat, in seconds."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def run_in_pty(cmd: list[str], warmup: float, seconds: float) -> tuple[int, float | None]:
    """Run ``cmd`` on a fresh 80x24 pseudo-terminal, draining its output; returns its exit
    code and its CPU fraction over [warmup + 1, warmup + seconds - 1] s from /proc."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", ROWS, COLS, 0, 0))
    env = dict(os.environ, TERM="xterm-256color", COLUMNS=str(COLS), LINES=str(ROWS))
    proc = subprocess.Popen(
        cmd,
        stdin=slave,
        stdout=slave,
        stderr=slave,
        env=env,
        start_new_session=True,
        cwd=HERE.parent,
    )
    os.close(slave)
    stop = threading.Event()

    def drain() -> None:
        while not stop.is_set():
            try:
                if not os.read(master, 65536):
                    return
            except OSError:
                return

    t = threading.Thread(target=drain, daemon=True)
    t.start()
    # the /proc cross-check: a window inside the child's own measuring span (rig open takes ~2 s)
    start = time.monotonic()
    samples: list[tuple[float, float]] = []
    while proc.poll() is None:
        el = time.monotonic() - start
        c = proc_cpu_s(proc.pid)
        if c is not None:
            samples.append((el, c))
        time.sleep(0.25)
    stop.set()
    os.close(master)
    frac = None
    lo, hi = warmup + 3.0, warmup + seconds
    inside = [(e, c) for e, c in samples if lo <= e <= hi]
    if len(inside) >= 2 and inside[-1][0] > inside[0][0]:
        frac = (inside[-1][1] - inside[0][1]) / (inside[-1][0] - inside[0][0])
    return proc.returncode, frac


def child(
    what: str, out: Path, warmup: float, seconds: float, tty: bool
) -> tuple[dict, float | None]:
    js = out / f"{what}.json"
    cmd = [
        sys.executable,
        str(CHILD),
        what,
        "--out",
        str(out),
        "--warmup",
        str(warmup),
        "--seconds",
        str(seconds),
        "--json",
        str(js),
    ]
    if tty:
        code, frac = run_in_pty(cmd, warmup, seconds)
    else:
        code, frac = subprocess.run(cmd, cwd=HERE.parent, check=False).returncode, None
    if code != 0 or not js.exists():
        raise RuntimeError(f"{what} child failed (exit {code}); see {out}/console.log")
    return json.loads(js.read_text()), frac


def verdict(ok: bool) -> str:
    return "PASS" if ok else "MISS"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="a 10 s measurement instead of 20 s")
    p.add_argument("--seconds", type=float, default=None)
    p.add_argument("--warmup", type=float, default=5.0)
    args = p.parse_args()
    seconds = args.seconds or (10.0 if args.quick else 20.0)
    with tempfile.TemporaryDirectory(prefix="fbs-console-bench-") as tmp:
        out = Path(tmp)
        log(
            f"console on an {COLS}x{ROWS} pty, rig sim?realtime=1, recording 16 channels at 1 kHz; "
            f"{args.warmup:g} s warm-up, {seconds:g} s measured"
        )
        base, _ = child("baseline", out, args.warmup, seconds, tty=False)
        con, proc_frac = child("console", out, args.warmup, seconds, tty=True)
    hz = con["paints"] / con["wall_s"]
    core = con["cpu_s"] / con["wall_s"]
    base_core = base["cpu_s"] / base["wall_s"]
    log(
        f"  recording            console: {con['samples']} samples, {con['gaps']} gaps, status {con['status']}; "
        f"baseline: {base['samples']} samples, {base['gaps']} gaps, status {base['status']}"
    )
    log(
        f"  meter refresh        {hz:6.1f} Hz    target >= {TARGET_HZ:g} Hz: ratio {hz / TARGET_HZ:5.2f}  "
        f"{verdict(hz >= TARGET_HZ)}"
    )
    log(
        f"  console process CPU  {core:6.3f} core  target < {TARGET_CORE:g} core: ratio {TARGET_CORE / core:5.2f}  "
        f"{verdict(core < TARGET_CORE)}"
        + (f"   (/proc cross-check {proc_frac:.3f})" if proc_frac is not None else "")
    )
    log(
        f"  baseline (no console: rig + recording in one process) {base_core:6.3f} core; "
        f"the console's own share {core - base_core:+.3f} core ({core / base_core:.2f} x the baseline)"
    )
    if hz < TARGET_HZ:
        log(f"TARGET MISSED: meter refresh {hz:.1f} Hz < {TARGET_HZ:g} Hz")
    if core >= TARGET_CORE:
        log(f"TARGET MISSED: console process {core:.3f} core >= {TARGET_CORE:g} core")
    if con["status"] != "complete" or con["gaps"]:
        log(f"TARGET MISSED: the console's recording was {con['status']} with {con['gaps']} gap(s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
