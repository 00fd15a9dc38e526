"""Start-up of the ``fbs`` command line (issue 37 item 9, acceptance D).

The figure: the wall time of ``fbs --version`` (the installed console script, a fresh process
each time), whose median must be under 0.4 s; it was 1.2-2.2 s when ``fbs.cli`` imported
every command and ``fbs demo``'s module pulled in the simulator, scipy, numba and python-can.
Its peak memory (``ru_maxrss``) is printed beside it.

Then each command's import cost, from the registry ``fbs.cli.COMMANDS``:

* ``options``: ``python -c "import fbs.MODULE"`` (the module that defines the command's
  options, which every ``fbs`` start imports) minus a bare ``python -c pass``;
* ``runs``: ``python -c "from fbs.cli import load; load(COMMAND)"`` (what the command imports
  when it runs: the rig, the simulator, the numerics, Textual) minus ``python -c "import
  fbs.cli"``: what that command adds to the start, and no other command pays.

Every figure is a median over ``--rounds`` rounds, the cases interleaved within each round so
that a change in the machine's load hits all of them; the baselines are measured in the same
rounds, and ``fbs --version`` is also given as a multiple of the bare interpreter's start. The
machine's load average is printed: on a busy machine every figure grows.

Benchmarks report, they never fail: the exit code is 0 and a missed target prints a
``TARGET MISSED`` line. Usage: ``python bench/cli_start.py [--quick] [--rounds N]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from fbs.cli import COMMANDS

TARGET_S = 0.4
ROOT = Path(__file__).resolve().parent.parent
FBS = Path(sys.executable).with_name("fbs")


def log(msg: str = "") -> None:
    print(msg, flush=True)


def load_average() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def timed(argv: list[str]) -> float:
    """Wall seconds of one run of ``argv`` (it must succeed)."""
    t0 = time.perf_counter()
    subprocess.run(argv, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def peak_rss_mb(argv: list[str]) -> float:
    """The peak resident memory of ``argv``, run in a child of its own (``ru_maxrss`` of the
    children is their maximum: a fresh child measures only ``argv``)."""
    code = (
        "import resource, subprocess, sys\n"
        "subprocess.run(sys.argv[1:], check=True, stdout=subprocess.DEVNULL)\n"
        "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, *argv], check=True, cwd=ROOT, capture_output=True, text=True
    )
    return int(out.stdout) / 1024  # Linux: KiB


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--quick", action="store_true", help="3 rounds")
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    rounds = 3 if args.quick else args.rounds
    py = sys.executable
    cases: dict[str, list[str]] = {
        "python -c pass": [py, "-c", "pass"],
        "fbs --version": [str(FBS), "--version"],
        "import fbs.cli": [py, "-c", "import fbs.cli"],
    }
    for name, c in COMMANDS.items():
        cases[f"options {name}"] = [py, "-c", f"import {c.module}"]
        cases[f"runs {name}"] = [py, "-c", f"from fbs.cli import load; load({name!r})"]
    log(
        f"{len(cases)} cases, {rounds} rounds; load average {load_average()}, "
        f"{os.cpu_count()} cores"
    )
    for argv in cases.values():  # untimed: the page cache and __pycache__ warm
        timed(argv)
    times: dict[str, list[float]] = {k: [] for k in cases}
    for _ in range(rounds):
        for k, argv in cases.items():
            times[k].append(timed(argv))
    med = {k: statistics.median(v) for k, v in times.items()}
    bare, version = med["python -c pass"], med["fbs --version"]
    rss_bare = peak_rss_mb(cases["python -c pass"])
    rss_version = peak_rss_mb(cases["fbs --version"])
    log(f"python -c pass     median {bare:6.3f} s  peak {rss_bare:5.0f} MB   (the baseline)")
    log(
        f"fbs --version      median {version:6.3f} s  peak {rss_version:5.0f} MB   "
        f"{version / bare:.1f}x the bare interpreter; runs "
        + " ".join(f"{t:.2f}" for t in times["fbs --version"])
    )
    log(f"import fbs.cli     median {med['import fbs.cli']:6.3f} s")
    log()
    log("seconds over the baseline, and as bare interpreter starts:")
    log("command      options (every start)   runs (that command only)")
    for name in COMMANDS:
        opt = med[f"options {name}"] - bare
        run = med[f"runs {name}"] - med["import fbs.cli"]
        log(f"{name:12s} {opt:+8.3f} s {opt / bare:6.1f}x    {run:+8.3f} s {run / bare:6.1f}x")
    log(f"load average after: {load_average()}")
    if version < TARGET_S:
        log(f"PASS: fbs --version median {version:.3f} s < {TARGET_S} s")
    else:
        log(f"TARGET MISSED: fbs --version median {version:.3f} s >= {TARGET_S} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
