"""What the coverage benchmarks share (``earth_rate_coverage``, ``stopwatch_coverage``): a sim
configuration as TOML, and the cases run in a spawn pool, one JSON line each as they finish."""

from __future__ import annotations

import json
import multiprocessing
import sys
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any


def toml_of(values: dict[str, dict[str, Any]]) -> str:
    """``{"gyro.X": {"k": v}}`` as TOML sections."""
    lines = []
    for section, kv in values.items():
        lines.append(f"[{section}]")
        lines += [f"{k} = {v!r}" for k, v in kv.items()]
    return "\n".join(lines) + "\n"


def _die_with_parent() -> None:
    """A pool worker ends with the bench (Linux's parent-death signal): a bench stopped by
    SIGTERM or SIGKILL left its workers running their campaigns into the kept folders."""
    import ctypes
    import signal

    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:  # not Linux: the workers outlive a killed bench, as before
        pass


def run_cases(
    run_case: Callable[..., dict[str, Any]], cases: list[tuple], jobs: int, out: str
) -> list[dict[str, Any]]:
    """``run_case(*case)`` for every case in a pool of ``jobs`` spawned processes; each record
    (a dict with ``seed`` and ``verdict`` or ``error``) is appended to ``out`` as it arrives."""
    recs: list[dict[str, Any]] = []
    with (
        open(out, "w") as jf,
        ProcessPoolExecutor(
            jobs, mp_context=multiprocessing.get_context("spawn"), initializer=_die_with_parent
        ) as pool,
    ):
        futs = [pool.submit(run_case, *case) for case in cases]
        for fut in as_completed(futs):
            rec = fut.result()
            recs.append(rec)
            jf.write(json.dumps(rec) + "\n")
            jf.flush()
            print(
                f"[{len(recs)}/{len(cases)}] seed {rec['seed']}: {rec.get('verdict', rec.get('error'))} "
                f"{rec.get('wall_s', '')} s",
                file=sys.stderr,
                flush=True,
            )
    return recs
