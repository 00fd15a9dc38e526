"""Scaling of ``fbs batch gap`` from one worker to two (issue 23, acceptance D).

One figure, measured in this run: the throughput (files per second, wall clock of the whole
command, worker start-up included) of the real command ``fbs batch gap FILES --jobs N --out
RESULTS.jsonl``, run as a subprocess over the same set of run files with the default local
process pool of 1 and of 2 workers. Target: 2 workers reach at least 1.7x the throughput of 1.

The run files are the detection-limit records of docs/gap.md section 6
(``fbs.campaign_task.simulate_record``): the nominal model and a few catalogue effects on axis
X, several seeds, made once in a temporary directory before any timing. There are 24 of them
because a file's analysis takes 0.5-3.5 s depending on what it finds: with 8 files the last
one or two ran alone on one worker while the other idled, and the ratio measured that tail
(1.53x idle, with 1.85x of the work in the tasks themselves), not the throughput of a batch of
thousands. Each configuration also reports the seconds its tasks took (the sum of the result
lines' ``elapsed_s``), so start-up and tail are visible as wall clock minus task time per worker. One untimed warm-up
batch loads numba's cache and the page cache; then the 1- and 2-worker batches run
interleaved (1, 2, 1, 2, ...), each a fresh ``--out``, and each configuration's median time
is its figure, so a change in the machine's load hits both. The result lines of the two
configurations must be the same apart from timing (``elapsed_s``): a difference prints
``RESULTS DIFFER``. With ``--scheduler`` the same is also run against an in-process Dask
``LocalCluster`` of 2 single-threaded worker processes (reported, no target).

The machine's core count (``os.cpu_count``, the cores this process may use) and its load
average before and after are printed: the ratio means little on a machine busy with other work.

Benchmarks report, they never fail: the exit code is 0 and a missed target prints a
``TARGET MISSED`` line. Usage: ``python bench/batch_scaling.py [--quick] [--scheduler]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

TARGET_RATIO = 1.7
#: the run files: every effect (its catalogue defaults) at every seed 1..N_SEEDS
EFFECTS = ("none", "pickup_line", "extra_damping", "flicker_noise")
#: the record length: the gap workflow needs at least 73.728 s
DURATION_S = 120.0
QUICK_DURATION_S = 80.0
N_SEEDS = 6
QUICK_SEEDS = 2
REPEAT = 3
QUICK_REPEAT = 2
#: keys that hold timings, left out when comparing the result lines
TIMING_KEYS = frozenset({"elapsed_s"})
ROOT = Path(__file__).resolve().parent.parent


def log(msg: str = "") -> None:
    print(msg, flush=True)


def machine() -> str:
    try:
        usable = str(len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        usable = "?"
    return f"os.cpu_count {os.cpu_count()}, usable by this process (sched_getaffinity) {usable}"


def load() -> str:
    try:
        one, five, fifteen = os.getloadavg()
    except OSError:
        return "load average unknown"
    return f"load average {one:.2f} {five:.2f} {fifteen:.2f} (1, 5, 15 min)"


def make_files(directory: Path, duration_s: float, n_seeds: int) -> list[str]:
    """The run files, simulated in this process (untimed)."""
    from fbs import campaign_task
    from simhw import effects

    files = []
    for effect in EFFECTS:
        params = {} if effect == "none" else {p.name: p.default for p in effects.get(effect).params}
        for seed in range(1, n_seeds + 1):
            path = directory / f"{effect}-{seed}.h5"
            campaign_task.simulate_record(path, effect, params, seed, duration_s)
            files.append(str(path))
    return files


def run_batch(files: list[str], out: Path, jobs: int, scheduler: str | None = None) -> float:
    """Wall-clock seconds of one ``fbs batch gap`` over ``files`` (a fresh ``out``); raises if it fails."""
    if out.exists():
        out.unlink()
    cmd = [
        sys.executable,
        "-m",
        "fbs",
        "batch",
        "gap",
        *files,
        "--jobs",
        str(jobs),
        "--out",
        str(out),
    ]
    if scheduler:
        cmd += ["--scheduler", scheduler]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(
            f"{' '.join(cmd[:6])} ... --jobs {jobs} exited {proc.returncode}:\n{proc.stderr[-3000:]}"
        )
    return seconds


def task_seconds(out: Path) -> float:
    """The seconds the tasks of ``out`` took, summed (each result line's ``elapsed_s``)."""
    return sum(
        float(json.loads(s).get("elapsed_s") or 0.0)
        for s in out.read_text().splitlines()
        if s.strip()
    )


def _strip(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _strip(v) for k, v in obj.items() if k not in TIMING_KEYS}
    if isinstance(obj, list):
        return [_strip(v) for v in obj]
    return obj


def results_of(out: Path) -> dict[str, Any]:
    """The result lines of ``out`` by file, timings left out."""
    lines = [json.loads(s) for s in out.read_text().splitlines() if s.strip()]
    return {rec["file"]: _strip(rec) for rec in lines}


def compare(name: str, ref: dict[str, Any], other: dict[str, Any]) -> bool:
    if ref == other:
        log(f"  results of {name}: identical to 1 worker's apart from timing ({len(ref)} files)")
        return True
    differ = sorted(f for f in set(ref) | set(other) if ref.get(f) != other.get(f))
    log(
        f"  RESULTS DIFFER: {name} against 1 worker, {len(differ)} file(s): {', '.join(differ[:5])}"
    )
    return False


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument(
        "--quick",
        action="store_true",
        help=f"{QUICK_DURATION_S:.0f} s records, {QUICK_REPEAT} repeats",
    )
    ap.add_argument(
        "--scheduler",
        action="store_true",
        help="also run against a local Dask cluster of 2 single-threaded workers",
    )
    args = ap.parse_args()
    duration = QUICK_DURATION_S if args.quick else DURATION_S
    repeat = QUICK_REPEAT if args.quick else REPEAT
    n_seeds = QUICK_SEEDS if args.quick else N_SEEDS

    log(f"machine: {machine()}")
    log(f"start: {load()}")
    ok = True
    with tempfile.TemporaryDirectory(prefix="fbs-batch-scaling-") as d:
        tmp = Path(d)
        t0 = time.perf_counter()
        files = make_files(tmp, duration, n_seeds)
        log(
            f"input: {len(files)} run files ({', '.join(EFFECTS)} x {n_seeds} seeds, {duration:.0f} s each), "
            f"made in {time.perf_counter() - t0:.0f} s (untimed)"
        )

        t0 = time.perf_counter()
        run_batch(files, tmp / "warm.jsonl", 2)
        log(f"warm-up (2 workers, untimed): {time.perf_counter() - t0:.1f} s")

        times: dict[int, list[float]] = {1: [], 2: []}
        for i in range(repeat):
            for jobs in (1, 2):
                out = tmp / f"jobs{jobs}.jsonl"
                s = run_batch(files, out, jobs)
                times[jobs].append(s)
                busy = task_seconds(out)
                log(
                    f"  round {i + 1}: {jobs} worker(s) {s:6.1f} s  {len(files) / s:.3f} files/s; "
                    f"tasks {busy:.1f} s, idle or starting {jobs * s - busy:.1f} worker-s"
                )
        ref = results_of(tmp / "jobs1.jsonl")
        ok &= compare("2 workers", ref, results_of(tmp / "jobs2.jsonl"))

        rate = {j: len(files) / statistics.median(t) for j, t in times.items()}
        ratio = rate[2] / rate[1]
        log(
            f"1 worker : {rate[1]:.3f} files/s (median of {repeat}: {statistics.median(times[1]):.1f} s)"
        )
        log(
            f"2 workers: {rate[2]:.3f} files/s (median of {repeat}: {statistics.median(times[2]):.1f} s)"
        )
        log(f"ratio 2/1: {ratio:.2f}x (target >= {TARGET_RATIO}x)")
        if ratio < TARGET_RATIO:
            log(
                f"TARGET MISSED: 2 workers reach {ratio:.2f}x one worker's throughput, target {TARGET_RATIO}x"
            )

        if args.scheduler:
            ok &= dask_run(files, tmp, repeat, ref, rate[1])
    log(f"end: {load()}")
    if not ok:
        log("RESULTS DIFFER between configurations (see above)")
    return 0


def dask_run(files: list[str], tmp: Path, repeat: int, ref: dict[str, Any], rate1: float) -> bool:
    """``--scheduler`` against an in-process LocalCluster of 2 single-threaded workers."""
    try:
        from distributed import LocalCluster
    except ImportError:
        log("dask: distributed not installed; skipped")
        return True
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        addr = cluster.scheduler_address
        run_batch(files, tmp / "dask-warm.jsonl", 2, addr)
        secs = [run_batch(files, tmp / "dask.jsonl", 2, addr) for _ in range(repeat)]
    rate = len(files) / statistics.median(secs)
    log(
        f"dask LocalCluster, 2 workers: {rate:.3f} files/s (median of {repeat}: {statistics.median(secs):.1f} s), "
        f"{rate / rate1:.2f}x the 1-worker pool (not interleaved with it; no target)"
    )
    return compare("dask 2 workers", ref, results_of(tmp / "dask.jsonl"))


if __name__ == "__main__":
    sys.exit(main())
