"""Run every benchmark in ``bench/`` (``make bench``).

Each ``bench/*.py`` other than this runner (and other than ``_*.py`` helpers) runs in sorted
order as its own process with this interpreter, from the repository root, its output
streamed as it comes. A final summary gives one line per benchmark with its exit code.
Benchmarks report and never fail on a missed target, so a nonzero exit code means the
benchmark itself broke; the runner then exits 1.
"""

from __future__ import annotations

import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent


@dataclass
class Outcome:
    name: str
    returncode: int
    seconds: float


def discover() -> list[Path]:
    """The benchmark scripts, in sorted order."""
    return sorted(
        p
        for p in HERE.glob("*.py")
        if p.resolve() != Path(__file__).resolve() and not p.name.startswith("_")
    )


def run_one(script: Path) -> Outcome:
    print(f"===== {script.name} " + "=" * max(0, 70 - len(script.name)), flush=True)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, str(script)], cwd=HERE.parent, check=False)
    return Outcome(script.name, proc.returncode, time.perf_counter() - t0)


def main() -> int:
    scripts = discover()
    if not scripts:
        print(f"no benchmarks found in {HERE}")
        return 0
    outcomes = [run_one(s) for s in scripts]
    print("===== summary " + "=" * 63)
    for o in outcomes:
        status = "ok" if o.returncode == 0 else "FAILED"
        print(f"{o.name:32s} exit {o.returncode:3d}  {status:6s}  ({o.seconds:.0f} s)")
    return 0 if all(o.returncode == 0 for o in outcomes) else 1


if __name__ == "__main__":
    sys.exit(main())
