"""What the coverage benchmarks share: a sim configuration as TOML, the drawn platform
(``draw_plant``), and the cases run in a spawn pool, one JSON line each as they finish."""

from __future__ import annotations

import json
import math
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


def log_uniform(rng: Any, lo: float, hi: float) -> float:
    """A number drawn log-uniformly from ``lo .. hi``."""
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


#: the bearing models a drawn axis may have (DESIGN section 7)
BEARINGS = ("none", "viscous", "spring", "dahl")


def draw_plant(rng: Any, nom: Any) -> dict[str, dict[str, Any]]:
    """The platform part of a drawn rig as TOML sections, about the data sheet ``nom`` (a
    ``SimConfig``): each compensation corner x0.9 .. 1.15, then per axis the inertia x0.7 .. 1.4
    and a bearing model from ``BEARINGS`` (To, eta, stiffness log-uniform x0.5 .. 2, viscous
    damping 0.01 .. 0.2 N m s), drawn in that order."""
    out: dict[str, dict[str, Any]] = {
        "compensation": {
            f"w{i}_rad_per_s": getattr(nom.compensation, f"w{i}_rad_per_s")
            * float(rng.uniform(0.9, 1.15))
            for i in range(1, 7)
        }
    }
    for a in ("X", "Y", "Z"):
        out[f"platform.{a}"] = {
            "inertia_kg_m2": nom.platform[a].inertia_kg_m2 * float(rng.uniform(0.7, 1.4))
        }
        b = nom.bearing[a]
        out[f"bearing.{a}"] = {
            "model": BEARINGS[int(rng.integers(len(BEARINGS)))],
            "To_Nm": b.To_Nm * log_uniform(rng, 0.5, 2.0),
            "eta_per_Nm": b.eta_per_Nm * log_uniform(rng, 0.5, 2.0),
            "stiffness_Nm_per_rad": b.stiffness_Nm_per_rad * log_uniform(rng, 0.5, 2.0),
            "damping_Nms": log_uniform(rng, 0.01, 0.2),
        }
    return out


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
    (a dict with ``seed`` and ``verdict`` or ``error``) is appended to ``out`` as it arrives.

    ``out`` is opened for appending: a campaign extended with ``--first`` into the same file
    keeps the rigs it already holds (hours of runs), and a reader takes a seed's latest record."""
    recs: list[dict[str, Any]] = []
    with (
        open(out, "a") as jf,
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
