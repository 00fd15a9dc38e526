"""Coverage of the hysteresis procedure's 95 % intervals (issue 18, build 1 and 4, acceptance A, B).

Each case is a sim rig with its own seed and, for all but the thesis-default cases, a random
gimbal bearing the procedure is never told: the swept axis X or Y, To 0.008-0.03 N m and eta
0.8e6-3e6 (N m)^-1 (log-uniform). ``fbs run hysteresis`` runs on it in virtual time; its angle
lag is measured on the record. Every figure's 95 % interval (``K_ci95``) is checked against the
configuration, resolved or not. Reported per figure: coverage (target 90-98 %), how often it was
resolved, the median and worst relative error, the median |error| over the interval's half
width; and the measured lag.

Benchmarks report, they never fail. Usage: ``python bench/hysteresis_coverage.py [--seeds 50]
[--defaults 5] [--jobs 1] [--out FILE.jsonl]``.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import math  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor, as_completed  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
#: the thesis's bearings (DESIGN.md section 3)
THESIS = {"X": (0.016, 1.6e6), "Y": (0.016, 1.48e6)}
FIGURES = ("To_Nm", "eta_per_Nm", "stiffness_Nm_per_rad")
log = logging.getLogger("hysteresis_coverage")


def draw(case: int, n_defaults: int) -> tuple[str, float, float, bool]:
    """(axis, To, eta, default?) of case ``case``: the first ``n_defaults`` are the thesis's bearings."""
    if case < n_defaults:
        axis = "XY"[case % 2]
        return (axis, *THESIS[axis], True)
    rng = np.random.default_rng([18, 5, case])
    axis = "XY"[int(rng.integers(2))]
    return (
        axis,
        float(rng.uniform(0.008, 0.03)),
        float(math.exp(rng.uniform(math.log(0.8e6), math.log(3e6)))),
        False,
    )


def run_case(case: int, n_defaults: int) -> dict[str, Any]:
    sys.path.insert(0, str(ROOT))
    from drivers.rig import open_rig
    from procedures.calibrations.hysteresis import Hysteresis, Params
    from procedures.runner import run_procedure

    axis, To, eta, default = draw(case, n_defaults)
    truth = {"To_Nm": To, "eta_per_Nm": eta, "stiffness_Nm_per_rad": eta * To * To}
    wall = time.monotonic()
    with tempfile.TemporaryDirectory() as tmp:
        url = f"sim?warm=1&seed={1000 + case}"
        if not default:
            cfg = Path(tmp) / "sim.toml"
            cfg.write_text(f"[bearing.{axis}]\nTo_Nm = {To!r}\neta_per_Nm = {eta!r}\n")
            url += f"&config={cfg}"
        with open_rig(url) as rig:
            s = run_procedure(Hysteresis(Params(axis=axis)), rig, Path(tmp) / "out")
        values = s.json_values(Hysteresis.json_keys)
    out: dict[str, Any] = {
        "case": case,
        "axis": axis,
        "default": default,
        "truth": truth,
        "status": s.status,
        "angle_lag_ms": values.get("angle_lag_ms"),
        "wall_s": time.monotonic() - wall,
    }
    for key in FIGURES:
        # each figure per axis (DESIGN.md section 7): {axis: value}, {axis: [lo, hi]}
        lo, hi = (values.get(f"{key}_ci95") or {}).get(axis) or (None, None)
        resolved = ((values.get("resolved") or {}).get(key) or {}).get(axis)
        value = (s.values.get(key) or {}).get(axis)
        out[key] = {
            "value": value,
            "ci95": [lo, hi],
            "resolved": resolved,
            "covered": lo is not None and hi is not None and lo <= truth[key] <= hi,
            "rel_error": None if value is None else value / truth[key] - 1.0,
            "error_over_half_width": None
            if value is None or lo is None or hi is None or hi <= lo
            else abs(value - truth[key]) / (0.5 * (hi - lo)),
        }
    return out


def report(rows: list[dict[str, Any]]) -> None:
    ok = [r for r in rows if r["status"] == "complete"]
    print(f"hysteresis coverage: {len(ok)} of {len(rows)} runs complete")
    for subset, name in (
        (ok, "all"),
        ([r for r in ok if r["default"]], "thesis defaults"),
        ([r for r in ok if not r["default"]], "random bearings"),
    ):
        if not subset:
            continue
        print(f"  {name} ({len(subset)} runs):")
        for key in FIGURES:
            cov = sum(r[key]["covered"] for r in subset)
            res = sum(bool(r[key]["resolved"]) for r in subset)
            errs = [abs(r[key]["rel_error"]) for r in subset if r[key]["rel_error"] is not None]
            ratio = [
                r[key]["error_over_half_width"]
                for r in subset
                if r[key]["error_over_half_width"] is not None
            ]
            print(
                f"    {key:22s} coverage {cov}/{len(subset)} = {100 * cov / len(subset):5.1f} %, resolved {res}, "
                f"|error| median {100 * statistics.median(errs):.2f} % max {100 * max(errs):.2f} %, "
                f"|error|/half-width median {statistics.median(ratio):.2f}"
                if errs and ratio
                else ""
            )
    lags = [r["angle_lag_ms"] for r in ok if r["angle_lag_ms"] is not None]
    if lags:
        print(
            f"  measured angle lag: median {statistics.median(lags):.3f} ms, range {min(lags):.3f}..{max(lags):.3f} ms"
        )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=50, help="runs in all (default 50)")
    ap.add_argument(
        "--defaults", type=int, default=6, help="of which with the thesis's bearings (default 6)"
    )
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", type=Path, help="one JSON line per run")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    rows: list[dict[str, Any]] = []
    t0 = time.monotonic()
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        futures = [pool.submit(run_case, i, args.defaults) for i in range(args.seeds)]
        for fut in as_completed(futures):
            try:
                row = fut.result()
            except Exception as exc:  # a benchmark reports, it never fails
                row = {"case": -1, "status": f"error: {exc}", "default": False}
            rows.append(row)
            if args.out:
                with args.out.open("a") as f:
                    f.write(json.dumps(row) + "\n")
            if row["status"] == "complete":
                print(
                    f"case {row['case']:3d} {row['axis']} {'default' if row['default'] else 'random '} "
                    f"lag {row['angle_lag_ms']:.3f} ms "
                    + " ".join(
                        f"{k.split('_')[0]} {100 * (row[k]['rel_error'] or math.nan):+.2f}%"
                        f"{'' if row[k]['covered'] else '(!)'}"
                        for k in FIGURES
                    ),
                    flush=True,
                )
            else:
                print(f"case {row['case']}: {row['status']}", flush=True)
    report(rows)
    print(f"{len(rows)} runs in {time.monotonic() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
