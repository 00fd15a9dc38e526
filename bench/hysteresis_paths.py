"""Which angle the bearing follows: the hysteresis fit along three paths, against the truth
(issue 38; ``procedures.analysis.hysteresis._drive_choice``).

The hysteresis analysis integrates Dahl's eq. 5.2 along the instrumentation angle low-passed
at the bandwidth whose fit explains the torque best. The bearing follows the platform's true
angle, which the autocollimator sees with its noise. Here the offline simulator records the
true angle too (``Simulator(truth=True)``), so on each rig the same torque is fitted along:

* ``analysis``: the product's own result (``analyze_file`` on the run file, its path of least
  residual);
* ``true``: the true angle, through the recorder's 3-pole anti-alias low-pass as the other
  channels are, its lag measured at the command's lines as the analysis measures the
  instrumentation angle's, at the top of the analysis's bandwidths;
* ``drive``: the analysis's path with its content above the chosen bandwidth taken from the
  drive (``dahl.driven_angle``), the bound ``_drive_choice`` takes.

Each rig: the swept axis X or Y, To 0.008-0.03 N m and eta 0.8e6-3e6 /N m (log-uniform), the
platform inertia x0.7-1.4 and the autocollimator's noise x0.6-1.6 (the data sheet follows the
inertia, never the bearing). The ladder is the procedure's (``HysteresisParams`` defaults: 0.4 Hz,
500 .. 5 urad, 1 + 6 cycles, 100 DAC updates a cycle, 400 Hz, the torque channel at +-0.2 V).

Prints per rig the relative errors of To, eta and eta To^2 along each path, and counts how often
the truth lies between the analysis's value and the drive's. Benchmarks report, they never fail.
Usage: ``python bench/hysteresis_paths.py [--rigs 8] [--first 0]``.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import math  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import scipy.signal  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

FIGURES = ("To", "eta", "k")


def draw(case: int) -> dict[str, float | str]:
    rng = np.random.default_rng([38, 7, case])
    return {
        "axis": "XY"[int(rng.integers(2))],
        "To": float(rng.uniform(0.008, 0.03)),
        "eta": float(math.exp(rng.uniform(math.log(0.8e6), math.log(3e6)))),
        "inertia_x": float(rng.uniform(0.7, 1.4)),
        "noise_x": float(rng.uniform(0.6, 1.6)),
    }


def record(case: int, rig: dict, path: Path) -> tuple[np.ndarray, object]:
    """The procedure's ladder on the offline simulator: a run file at ``path``, and the true
    angle of the swept axis (rad) sample for sample."""
    from daq.runfile import RunWriter
    from procedures.calibrations.hysteresis import HysteresisParams
    from simhw.config import SimConfig, from_dict
    from simhw.datasheet import rig_calibration
    from simhw.simulator import Simulator

    a = str(rig["axis"])
    base = SimConfig()
    cfg = from_dict(
        {
            "bearing": {a: {"To_Nm": rig["To"], "eta_per_Nm": rig["eta"]}},
            "platform": {a: {"inertia_kg_m2": base.platform[a].inertia_kg_m2 * rig["inertia_x"]}},
            "autocollimator": {a: {"nea_urad": base.autocollimator[a].nea_urad * rig["noise_x"]}},
        }
    )
    cal = rig_calibration(cfg)
    p = HysteresisParams(axis=a)
    lo = a.lower()
    names = (f"cmd_{lo}", f"ac_{lo}_inst", f"pa_{lo}")
    sim = Simulator(cfg, rate_hz=p.rate_hz, seed=case, mode=3, truth=True, channels=names)
    sim.set_range(f"pa_{lo}", 0.2)
    per = int(round(p.rate_hz / (p.frequency_hz * p.updates_per_cycle)))
    volts_per_urad = cal.autocollimator[a].control_mV_per_urad * 1e-3
    blocks = [sim.advance(int(2 * p.rate_hz))]
    for amp in p.amplitudes_urad:
        for k in range((p.settle_cycles + p.cycles) * p.updates_per_cycle):
            phase = 2 * math.pi * (k + 0.5) / p.updates_per_cycle
            sim.set_ac_bias_V(a, -amp * volts_per_urad * math.sin(phase))
            blocks.append(sim.advance(per))
    sim.set_ac_bias_V(a, 0.0)
    blocks.append(sim.advance(int(p.rate_hz / p.frequency_hz)))
    cols = {n: np.concatenate([b[n] for b in blocks]) for n in names}
    with RunWriter(
        path,
        rig="sim-offline",
        mode=3,
        rate_hz=p.rate_hz,
        channels=dict.fromkeys(cols, "V"),
        axis=a,
        meta={"calibration": dataclasses.asdict(cal)},
    ) as wr:
        wr.append(cols)
    return np.concatenate([b[f"theta_{lo}"] for b in blocks]), cal


def run_case(case: int) -> dict:
    from daq.reader import RunFile
    from procedures.analysis import dahl
    from procedures.analysis import hysteresis as hy

    rig = draw(case)
    a = str(rig["axis"])
    lo = a.lower()
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / "sweep.h5"
        true, cal = record(case, rig, f)
        res = hy.analyze_file(f, a)
        with RunFile(f) as rf:
            cmd, inst, pa = rf.read([f"cmd_{lo}", f"ac_{lo}_inst", f"pa_{lo}"])
            fs = rf.rate_hz
    plat = cal.platform[a]
    fc = res.torque_cutoff_hz
    segs = dahl.find_segments(cmd, fs, res.frequency_hz, settle_cycles=1)
    step = max(1, int(fs / (8.0 * fc)))
    cutoffs = res.scan.cutoff_hz  # the bandwidths the analysis tried
    truth = {"To": rig["To"], "eta": rig["eta"], "k": rig["eta"] * rig["To"] ** 2}
    out = {"case": case, **rig, "cutoff_hz": res.path_cutoff_hz, "inertia": plat.inertia_kg_m2}
    out["analysis"] = {"To": res.To_Nm, "eta": res.eta_per_Nm, "k": res.stiffness_Nm_per_rad}

    # the true angle as the recorder sees the others: its 3-pole anti-alias low-pass
    sos = scipy.signal.butter(3, 0.3 * fs, fs=fs, output="sos")
    seen = scipy.signal.sosfilt(sos, true)
    rigid = hy.rigid_response(plat)
    lag = dahl.measure_lag(
        cmd, seen, pa, fs, res.frequency_hz, segs, rigid, min_hz=2 * fc, max_hz=0.45 * fs
    ).lag_s
    theta, _, torque, _ = hy._torque(seen, pa, fs, fc, plat, lag)
    fit = dahl.fit_dahl(
        dahl.lowpass(theta, fs, max(cutoffs)), torque, segs, fs, smooth_hz=fc, step=step
    )
    out["true"] = {"To": fit.To_Nm, "eta": fit.eta_per_Nm, "k": fit.stiffness_Nm_per_rad}

    # the drive's view above the analysis's bandwidth, as ``_drive_choice`` takes it
    angle = inst / (cal.autocollimator[a].inst_mV_per_urad * 1e-3 / 1e-6)
    theta, _, torque, _ = hy._torque(angle, pa, fs, fc, plat, res.angle_lag_s)
    best = dahl.fit_dahl(
        dahl.lowpass(theta, fs, res.path_cutoff_hz), torque, segs, fs, smooth_hz=fc, step=step
    )
    best.path_cutoff_hz = res.path_cutoff_hz
    down, up = hy._drive_choice(theta, torque, pa, fs, fc, plat, segs, step, cutoffs, best)
    shift = np.exp(up - down)
    out["drive"] = {
        "To": res.To_Nm * shift[0],
        "eta": res.eta_per_Nm * shift[1],
        "k": res.stiffness_Nm_per_rad * shift[2],
    }
    out["truth"] = truth
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rigs", type=int, default=8)
    ap.add_argument("--first", type=int, default=0)
    args = ap.parse_args(argv)
    rows = []
    head = "  ".join(f"{p:>20s}" for p in ("analysis", "true", "drive"))
    print(f"case axis sqrt(k/I) Hz cutoff Hz  {head}   (To, eta, eta To^2: error %)")
    for case in range(args.first, args.first + args.rigs):
        r = run_case(case)
        rows.append(r)
        f_k = math.sqrt(r["truth"]["k"] / r["inertia"]) / (2 * math.pi)
        cells = []
        for path in ("analysis", "true", "drive"):
            cells.append(
                " ".join(f"{100 * (r[path][f] / r['truth'][f] - 1):+6.2f}" for f in FIGURES)
            )
        row = "  ".join(f"{c:>20s}" for c in cells)
        print(f"{case:4d} {r['axis']:>4s} {f_k:12.1f} {r['cutoff_hz']:9.1f}  {row}", flush=True)
    print("\nrelative error, % (To, eta, eta To^2): median [min, max]")
    for path in ("analysis", "true", "drive"):
        parts = []
        for f in FIGURES:
            e = [100 * (r[path][f] / r["truth"][f] - 1) for r in rows]
            parts.append(f"{f} {statistics.median(e):+.2f} [{min(e):+.2f}, {max(e):+.2f}]")
        print(f"  {path:8s} " + "; ".join(parts))
    for f in FIGURES:
        between = sum(
            min(r["analysis"][f], r["drive"][f])
            <= r["truth"][f]
            <= max(r["analysis"][f], r["drive"][f])
            for r in rows
        )
        print(f"  truth between the analysis's and the drive's {f}: {between}/{len(rows)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
