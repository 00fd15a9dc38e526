"""Coverage of the excitation procedure's 95 % intervals (issue 38 items 2 and 3).

Each case is a sim rig drawn here and published nowhere the procedure looks: the axis X or Y,
the inertia x0.7-1.4, the compensation network's corners w1-w4 each x0.9-1.15, the gyro
gimbals' damping x0.8-1.25, and a bearing of every model on the axis: ``dahl`` (To 0.008-0.03
N m, eta 0.8e6-3e6 (N m)^-1, log-uniform, kept to small-motion stiffness 150-900 N m/rad),
``viscous`` (0.02-0.5 N m s), ``spring`` (200-700 N m/rad) or ``none``; the first cases are the
thesis rig (Dahl, all defaults). A drawn rig whose linearized Mode-3 loop is not stable with
margin is drawn again (a lab's is). ``fbs run excitation`` runs on it in virtual time with the
procedure's defaults.

Truths: the network's corners and the inertia are the config's. The stiffness and the damping
of a linear bearing are its constants (the damping with the gyro gimbals'); of a Dahl bearing
they are what the bearing is under that run's excitation: its torque along the true angle of
an offline run at the same level, fitted as the procedure fits
(``fbs.demo_truth.dahl_equivalent_linear``). Dahl's sinusoidal describing function (eq. 5.12)
at the amplitude the run reports (``dahl_at_amplitude``) is recorded beside it
(``df_stiffness_Nm_per_rad``, ``df_damping_Nms``): it reads k 2-7 % high, for the loop's noise
dithers the friction and the motion is broadband. Reported per figure and bearing model: n, how often resolved,
coverage of the resolved intervals, coverage of the unresolved intervals, the median and worst
relative error.

The run files are kept under ``--keep DIR`` (one per case) so that an analysis can be repeated
on them (``--reanalyse``) without simulating again.

Benchmarks report, they never fail. Usage: ``python bench/excitation_coverage.py [--cases 12]
[--defaults 1] [--jobs 1] [--keep DIR] [--reanalyse] [--out FILE.jsonl]``.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import math  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))
from coverage_pool import run_cases, toml_of  # noqa: E402

CORNERS = ("w1_rad_per_s", "w2_rad_per_s", "w3_rad_per_s", "w4_rad_per_s")
NOMINAL = {"w1_rad_per_s": 0.15, "w2_rad_per_s": 10.0, "w3_rad_per_s": 30.0, "w4_rad_per_s": 200.0}
MODELS = ("dahl", "viscous", "spring", "none")


def draw(case: int, n_defaults: int) -> tuple[str, dict[str, dict[str, Any]]]:
    """(axis, sim config) of ``case``; the first ``n_defaults`` the thesis rig on X."""
    if case < n_defaults:
        return "X", {}
    sys.path.insert(0, str(ROOT))
    from simhw.config import SimConfig, load_config
    from simhw.plant import linearized_poles

    rng = np.random.default_rng([38, 2, case])
    while True:
        axis = "XY"[int(rng.integers(2))]
        base = SimConfig()
        model = MODELS[int(rng.integers(len(MODELS)))]
        bearing: dict[str, Any] = {"model": model}
        if model == "dahl":
            while True:
                To = float(rng.uniform(0.008, 0.03))
                eta = float(math.exp(rng.uniform(math.log(0.8e6), math.log(3e6))))
                if 150.0 <= eta * To * To <= 900.0:
                    break
            bearing |= {"To_Nm": round(To, 5), "eta_per_Nm": round(eta, -3)}
        elif model == "viscous":
            bearing["damping_Nms"] = round(
                float(math.exp(rng.uniform(math.log(0.02), math.log(0.5)))), 4
            )
        elif model == "spring":
            bearing["stiffness_Nm_per_rad"] = round(float(rng.uniform(200, 700)), 1)
        plat = {
            "inertia_kg_m2": round(
                base.platform[axis].inertia_kg_m2 * float(rng.uniform(0.7, 1.4)), 4
            ),
            "gyro_damping_Nms": round(
                base.platform[axis].gyro_damping_Nms * float(rng.uniform(0.8, 1.25)), 4
            ),
        }
        comp = {k: round(v * float(rng.uniform(0.9, 1.15)), 4) for k, v in NOMINAL.items()}
        cfg = {f"platform.{axis}": plat, f"bearing.{axis}": bearing, "compensation": comp}
        import tempfile

        with tempfile.TemporaryDirectory() as d:
            p = Path(d) / "rig.toml"
            p.write_text(toml_of(cfg))
            lin = linearized_poles(load_config(p), 3, axis)
        if np.max(lin.real) < -0.05:
            return axis, cfg


def truths(
    cfg_path: Path | None, axis: str, amplitude_urad: float | None, level_V_rms: float | None
) -> dict[str, float | None]:
    from fbs.demo_truth import dahl_at_amplitude, dahl_equivalent_linear
    from simhw.config import SimConfig, load_config

    cfg = load_config(cfg_path) if cfg_path else SimConfig()
    comp = cfg.compensation
    out: dict[str, float | None] = {k: getattr(comp, k) for k in CORNERS}
    pa = cfg.platform[axis]
    out["inertia_kg_m2"] = pa.inertia_kg_m2
    b = cfg.bearing[axis]
    if b.model == "dahl":
        k0 = b.eta_per_Nm * b.To_Nm**2
        w = math.sqrt(k0 / pa.inertia_kg_m2)
        out["stiffness_Nm_per_rad"] = out["damping_Nms"] = None
        if level_V_rms is not None:
            eq = dahl_equivalent_linear(cfg, axis, level_V_rms)
            out["stiffness_Nm_per_rad"], out["damping_Nms"] = (
                eq.stiffness_Nm_per_rad,
                eq.damping_Nms,
            )
            out["offline_motion_urad_rms"] = eq.motion_urad_rms
        if amplitude_urad is not None:
            k, d, _ = dahl_at_amplitude(cfg, axis, amplitude_urad, w)
            out["df_stiffness_Nm_per_rad"] = k
            out["df_damping_Nms"] = pa.gyro_damping_Nms + pa.extra_damping_Nms + d
        out["small_motion_stiffness"] = k0
    else:
        k, d, _ = dahl_at_amplitude(cfg, axis, 1.0, 1.0)
        out["stiffness_Nm_per_rad"] = k
        out["damping_Nms"] = pa.gyro_damping_Nms + pa.extra_damping_Nms + d
    return out


def _figures(values: dict[str, Any], axis: str) -> dict[str, dict[str, Any]]:
    """Every platform and network figure as {value, ci95, resolved, amplitude}."""
    out: dict[str, dict[str, Any]] = {}
    net = values.get("network") or {}
    for k in CORNERS:
        out[k] = {
            "value": net.get(k),
            "ci95": net.get(f"{k}_ci95"),
            "resolved": (net.get("resolved") or {}).get(k),
            "why": (net.get("why_unresolved") or {}).get(k),
        }
    for k in ("inertia_kg_m2", "damping_Nms", "stiffness_Nm_per_rad"):
        out[k] = {
            "value": (values.get(k) or {}).get(axis),
            "ci95": (values.get(f"{k}_ci95") or {}).get(axis),
            "resolved": ((values.get("resolved") or {}).get(k) or {}).get(axis),
        }
    return out


def amplitude_of(values: dict[str, Any], axis: str) -> float | None:
    a = values.get("excitation_amplitude_urad")
    if isinstance(a, dict):
        a = a.get(axis)
    return None if a is None else float(a)


def run_case(case: int, n_defaults: int, keep: str, reanalyse: bool) -> dict[str, Any]:
    sys.path.insert(0, str(ROOT))
    import logging

    logging.disable(logging.WARNING)
    from drivers.rig import open_rig
    from procedures.calibrations.excitation import Excitation, Params
    from procedures.resume import load_resume
    from procedures.runner import run_procedure

    axis, cfg = draw(case, n_defaults)
    folder = Path(keep) / f"case{case:03d}"
    folder.mkdir(parents=True, exist_ok=True)
    cfg_path = None
    url = f"sim?warm=1&seed={3800 + case}"
    if cfg:
        cfg_path = folder / "rig.toml"
        cfg_path.write_text(toml_of(cfg))
        url += f"&config={cfg_path}"
    wall = time.monotonic()
    proc = Excitation(Params(axis=axis))
    files = sorted(folder.glob("excitation*.h5"))
    with open_rig(url) as rig:
        if reanalyse and files:
            s = run_procedure(
                proc,
                rig,
                folder,
                resume=load_resume(files[-1], Excitation, complete_ok=True),
                report=False,
            )
        else:
            s = run_procedure(proc, rig, folder, report=False)
    values = s.json_values(Excitation.json_keys)
    model = (cfg.get(f"bearing.{axis}") or {}).get("model", "dahl")
    amp = amplitude_of(values, axis)
    level = s.values.get("level_V_rms")
    truth = truths(cfg_path, axis, amp, None if level is None else float(level))
    rec: dict[str, Any] = {
        "seed": case,
        "case": case,
        "axis": axis,
        "bearing": model,
        "config": cfg,
        "status": s.status,
        "verdict": str(s.verdict),
        "error": s.error,
        "amplitude_urad": amp,
        "level_limited_by": s.values.get("level_limited_by"),
        "truth": truth,
        "wall_s": round(time.monotonic() - wall, 1),
    }
    figs = _figures(values, axis)
    for k, fig in figs.items():
        t = truth.get(k)
        lo, hi = fig["ci95"] or (None, None)
        fig["covered"] = None if t is None or lo is None or hi is None else bool(lo <= t <= hi)
        fig["rel_error"] = None if t is None or fig["value"] is None else fig["value"] / t - 1.0
        fig["truth"] = t
    rec["figures"] = figs
    return rec


def table(recs: list[dict[str, Any]]) -> str:
    rows = [
        "figure | bearing | n | resolved | covered (resolved) | covered (unresolved) | median |err| | max |err|"
    ]
    keys = [*CORNERS, "inertia_kg_m2", "damping_Nms", "stiffness_Nm_per_rad"]
    for k in keys:
        for model in (*MODELS, "all"):
            sel = [
                r["figures"][k]
                for r in recs
                if "figures" in r and (model == "all" or r["bearing"] == model)
            ]
            sel = [f for f in sel if f.get("truth") is not None]
            if not sel:
                continue
            res = [f for f in sel if f["resolved"]]
            unr = [f for f in sel if not f["resolved"]]
            errs = [abs(f["rel_error"]) for f in res if f["rel_error"] is not None]
            rows.append(
                f"{k} | {model} | {len(sel)} | {len(res)} | {sum(bool(f['covered']) for f in res)}/{len(res)} | "
                f"{sum(bool(f['covered']) for f in unr)}/{len(unr)} | "
                f"{statistics.median(errs) if errs else float('nan'):.3%} | "
                f"{max(errs) if errs else float('nan'):.3%}"
            )
    return "\n".join(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=12)
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--defaults", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--keep", default="/tmp/excitation_coverage")
    ap.add_argument(
        "--reanalyse", action="store_true", help="analyse the kept run files again, no new runs"
    )
    ap.add_argument("--out", default="excitation_coverage.jsonl")
    a = ap.parse_args()
    cases = [(c, a.defaults, a.keep, a.reanalyse) for c in range(a.first, a.first + a.cases)]
    recs = run_cases(run_case, cases, a.jobs, a.out)
    recs.sort(key=lambda r: r["case"])
    for r in recs:
        f = r.get("figures") or {}
        line = " ".join(f"{k.split('_')[0]} {_fmt(v)}" for k, v in f.items())
        t = r.get("truth") or {}
        df = (
            f" | sinusoidal DF k {t['df_stiffness_Nm_per_rad']:.4g} D {t['df_damping_Nms']:.4g}"
            if "df_stiffness_Nm_per_rad" in t
            else ""
        )
        print(
            f"case {r['case']} {r['axis']} {r['bearing']} amp {r.get('amplitude_urad')}: {line}{df}"
        )
    print(table(recs))


def _fmt(f: dict[str, Any]) -> str:
    ci = f.get("ci95") or [None, None]
    v = f.get("value")
    mark = "" if f.get("covered") else " MISS"
    return (
        (
            f"{'-' if v is None else f'{v:.4g}'} [{ci[0]:.4g}, {ci[1]:.4g}]{'' if f.get('resolved') else ' (unres)'}"
            f" /{f.get('truth'):.4g}{mark}"
        )
        if ci[0] is not None and f.get("truth") is not None
        else "?"
    )


if __name__ == "__main__":
    main()
