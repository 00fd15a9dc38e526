"""One run of ``fbs campaign gap``, as a worker runs it: simulate the detection-limit record with
an effect injected (or none: a null run), run the model-gap workflow on it, and return the
run's line of ``runs.jsonl``.

The record is the one docs/gap.md section 6 measures the detection limits on (the suite
``tests/procedures/analysis/gap/test_hidden_effects.py``): ``simhw``'s nominal model (gimbal
bearings off, ``simhw.effects.nominal``) with the effect on axis X, Mode 3, 1 kHz, the axis's
channels ``ac_x_ctl``, ``ac_x_inst``, ``gyro_x``, ``pa_x`` on ADC ranges of 1, 1, 1 and 0.05 V,
300 s unless the campaign shortens it. The same seed gives the same samples on any machine, so a
run's result does not depend on where it ran. The record is written to the worker's temporary
scratch directory (``fbs.scratch``: one a killed worker left is removed by the next run) and
removed after the analysis; the workflow is what ``fbs gap FILE --json`` runs
(``analyse`` with its default options), its errors ended as that command ends them
(``fbs.batch_task.guarded``).

Like ``fbs.batch_task``, this module imports no numerics at import time: a worker sets its
environment (one BLAS thread, the numba cache) before numpy and numba load.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fbs import batch_task
from fbs.scratch import scratch_dir

#: the record of docs/gap.md section 6
MODE = 3
AXIS = "X"
RATE_HZ = 1000.0
DURATION_S = 300.0
#: channel -> ADC range (V) (tests/procedures/analysis/gap/conftest.py ``HIDDEN_RANGES_V``)
RANGES_V = {"ac_x_ctl": 1.0, "ac_x_inst": 1.0, "gyro_x": 1.0, "pa_x": 0.05}
#: the simulator's output block
BLOCK_S = 10.0
#: the keys of a line of ``runs.jsonl``, in order
RUN_KEYS = (
    "effect",
    "grid",
    "params",
    "seed",
    "record",
    "exit",
    "named",
    "significant",
    "explained",
    "fitted",
    "fitted_ci95",
    "gap_before_db",
    "gap_after_db",
    "warnings",
    "error",
    "elapsed_s",
)


def record_spec(duration_s: float = DURATION_S) -> dict[str, Any]:
    """What a run's record is, as its line states it."""
    return {"duration_s": duration_s, "rate_hz": RATE_HZ, "mode": MODE, "axis": AXIS}


def simulate_record(
    path: str | Path,
    effect: str,
    params: dict[str, float],
    seed: int,
    duration_s: float = DURATION_S,
) -> Path:
    """The detection-limit record with ``effect`` at ``params`` (``"none"``: nominal), seed
    ``seed``, written as an fbs-run file with the axis attribute."""
    from daq.runfile import RunWriter
    from simhw import effects
    from simhw.simulator import Simulator

    cfg = effects.nominal()
    spec = []
    if effect != "none":
        cfg = effects.get(effect).inject(cfg, AXIS, **params)
        spec = [effect + ":" + ",".join(f"{k}={v!r}" for k, v in params.items())]
    sim = Simulator(
        cfg, RATE_HZ, seed=seed, mode=MODE, channels=tuple(RANGES_V)
    )  # the recorded channels only
    for c, r in RANGES_V.items():
        sim.set_range(c, r)
    with RunWriter(
        path,
        rig="sim-offline",
        mode=MODE,
        rate_hz=RATE_HZ,
        channels=dict.fromkeys(RANGES_V, "V"),
        axis=AXIS,
        meta={"effects": spec, "seed": seed},
        overwrite=True,
    ) as w:
        for block in sim.run(duration_s, BLOCK_S):
            w.append({c: block[c] for c in RANGES_V})
    return Path(path)


def _simulate_and_analyse(
    effect: str, params: dict[str, float], seed: int, duration_s: float
) -> dict[str, Any]:
    from procedures.analysis.gap.workflow import analyse

    with scratch_dir("fbs-campaign-") as d:
        path = simulate_record(d / f"{effect}-{seed}.h5", effect, params, seed, duration_s)
        res = analyse(path)
        return {"json": res.to_json(), "warnings": list(res.warnings)}


def run(
    effect: str, grid: str | None, params: dict[str, float], seed: int, duration_s: float
) -> dict[str, Any]:
    """One run of the campaign, in this process, as its line of ``runs.jsonl``: ``named`` the
    effects the workflow named, in the order found; ``fitted`` (and ``fitted_ci95``) the
    parameters it gave the injected effect where it named it (empty for a null run or an effect
    it did not name); ``exit`` and ``error`` as ``fbs gap`` would end (0 and null; 2 and the
    message; 1 and the traceback)."""
    batch_task.prepare_process()
    from fbs.cli import load

    load("simulate", "gap")  # the numerics load here, not in the run's elapsed_s

    batch_task.limit_loaded_blas()
    code, out, error, elapsed = batch_task.guarded(
        _simulate_and_analyse, effect, params, seed, duration_s
    )
    line: dict[str, Any] = dict.fromkeys(RUN_KEYS)
    line |= {
        "effect": effect,
        "grid": grid,
        "params": dict(params),
        "seed": seed,
        "record": record_spec(duration_s),
        "exit": code,
        "error": error,
        "elapsed_s": round(elapsed, 3),
        "named": [],
        "fitted": {},
        "fitted_ci95": {},
        "warnings": [],
    }
    if out is not None:
        j = out["json"]
        found = {e["effect"]: e for e in j["effects"]}
        mine = found.get(effect, {})
        line |= {
            "named": list(found),
            "significant": bool(j["significant"]),
            "explained": bool(j["explained"]),
            "fitted": mine.get("parameters", {}),
            "fitted_ci95": mine.get("parameters_ci95", {}),
            "gap_before_db": j["gap_before_db"],
            "gap_after_db": j["gap_after_db"],
            "warnings": out["warnings"],
        }
    return line
