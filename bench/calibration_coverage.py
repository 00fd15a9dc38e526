"""Coverage of earth-rate's K_TO and stopwatch's K_g 95 % intervals on rigs drawn independently
(issue 38 item 4).

Each rig (``draw_rig``, seeded by ``[38, seed]``) is a sim configuration the procedures are
never told:

* site latitude uniform -60 .. +72 deg; the rotary table base's azimuth offset +-5 deg;
* platform inertia x0.7 .. 1.4 per axis; each compensation corner w1..w6 x0.9 .. 1.15;
* a bearing model per axis drawn from none / viscous / spring / dahl (To, eta, stiffness x0.5 .. 2,
  viscous damping 0.01 .. 0.2 N m s);
* the primary autocollimator's NEA x0.6 .. 2 with a common X/Y part 0 .. 0.6;
* per gyro channel: K_TO x0.85 .. 1.15, K_g x0.8 .. 1.2, fixed drift +-1.5 urad/s, g-drifts
  +-0.15 urad/s/g along each axis, restraint h/k x0.85 .. 1.15 of the data sheet's, ARW
  log-uniform 0.003 .. 0.5 urad/sqrt(s), bias instability log-uniform 0.005 .. 0.1 urad/s,
  pickoff noise x0.6 .. 2 (its lines scaled with it).

On each rig ``earth-rate`` runs, then ``stopwatch`` with K_TO given as the rig's true value (the
stopwatch's own error, as an audit that hands it a known K_TO sees it: a given K_TO carries no
interval). The campaign's K_g (the stopwatch with the earth-rate K_TO and its interval, as ``fbs
demo`` chains them) follows exactly, K_g going as 1 / K_TO: ``K_g (K_TO true / K_TO found)``, the
relative half-widths in quadrature (``Stopwatch.kto_rel_half_width``, ``kg_estimate``); it is
printed as ``K_g (campaign)``.

Every record keeps the steps' results (stations, ramps), so ``--reanalyze F.jsonl`` measures a
changed analysis again without running the rigs (a change to the steps needs new runs).

Measured. Before (main at a5a17d0), seeds 0-19; after, seeds 0-39 (0-19 the same records: the
earth-rate ones analysed again by ``--reanalyze``, the stopwatch run again after its step changed,
same noise; 20-39 drawn after the changes were made):

| figure | before (20 rigs): covered, median / max error | after (40 rigs) |
|---|---|---|
| K_TO X | 20/20, 0.013 / 0.085 % | 40/40, 0.013 / 0.106 % |
| K_TO Y | 19/20, 0.019 / 0.152 % | 39/40, 0.015 / 0.152 % |
| K_TO Z | 20/20, 0.151 / 0.395 %, +-0.55..1.7 % | 38/40, 0.193 / 1.81 %, +-0.43..1.8 % (median +-0.86) |
| K_TO XRD | 20/20 (20-39 before the change: 16/20) | 40/40, 0.031 / 0.113 %, median +-0.16 % (was +-0.09) |
| K_g, K_TO given, X | 18/20, 0.145 / 0.197 % (misses +0.18 % +-0.05, +0.16 % +-0.14) | 39/40, 0.051 / 0.286 % |
| K_g, K_TO given, Y | 19/20, 0.156 / 0.492 % | 40/40, 0.102 / 0.303 % |
| K_g, K_TO given, Z / XRD | 20/20, 20/20 | 40/40, 40/40 |
| K_g as the campaign chains it | 78/80 | 160/160 |
| all intervals | 234/240 (97.5 %) | 476/480 (99.2 %) |

Left: Z's two misses (seed 23, -1.81 % +-1.82 % at -46 deg, bias instability 0.096; seed 29,
-0.50 % +-0.45 % at -7 deg; noise-free at -46 and +52 deg Z reads within 0.02 %), Y's K_TO
(seed 3, -0.03 % +-0.03 %), X's K_g (seed 11, +0.12 % +-0.09 %, ARW 0.16 urad/sqrt(s)); the
K_g intervals over-cover (the partner-transient bound is conservative). No rig was unresolved.

Prints per figure and channel: n, covered (the 95 % interval holds the truth, resolved or not),
median and max |relative error| of the resolved values, the median relative half-width, and
the unresolved share. Benchmarks report, they never fail. Each rig costs about 7200 s of rig
time (~2 min of wall time on an idle core). Usage: ``python bench/calibration_coverage.py
[--rigs 20] [--first 0] [--jobs 1] [--out F.jsonl] [--keep DIR]`` or ``--reanalyze F.jsonl``.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from types import SimpleNamespace  # noqa: E402
from typing import TYPE_CHECKING, Any  # noqa: E402

import numpy as np  # noqa: E402
from coverage_pool import draw_plant, log_uniform, run_cases, toml_of  # noqa: E402

if TYPE_CHECKING:
    from procedures.procedure import Procedure

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
CHANNELS = ("X", "Y", "Z", "XRD")


def draw_rig(seed: int) -> dict[str, dict[str, Any]]:
    """The rig of ``seed`` as TOML sections (the module docstring's distribution)."""
    from simhw.config import SimConfig

    nom = SimConfig()
    rng = np.random.default_rng([38, seed])
    cfg: dict[str, dict[str, Any]] = {
        "site": {"latitude_deg": round(float(rng.uniform(-60.0, 72.0)), 3)},
        "table": {"base_azimuth_offset_deg": round(float(rng.uniform(-5.0, 5.0)), 4)},
    }
    cfg |= draw_plant(rng, nom)
    nea, common = float(rng.uniform(0.6, 2.0)), round(float(rng.uniform(0.0, 0.6)), 3)
    for a in ("X", "Y"):
        cfg[f"autocollimator.{a}"] = {
            "nea_urad": nom.autocollimator[a].nea_urad * nea,
            "common_noise_fraction": common,
        }
    for ch in CHANNELS:
        g = nom.gyro[ch]
        k = float(rng.uniform(0.6, 2.0))
        cfg[f"gyro.{ch}"] = {
            "torquer_scale_urad_per_s_per_V": round(
                g.torquer_scale_urad_per_s_per_V * float(rng.uniform(0.85, 1.15)), 5
            ),
            "pickoff_scale_mV_per_urad": round(
                g.pickoff_scale_mV_per_urad * float(rng.uniform(0.8, 1.2)), 5
            ),
            "fixed_drift_urad_per_s": round(float(rng.uniform(-1.5, 1.5)), 4),
            **{
                f"g_drift_{x}_urad_per_s_per_g": round(float(rng.uniform(-0.15, 0.15)), 4)
                for x in "xyz"
            },
            "restraint_time_s": g.restraint_time_s * float(rng.uniform(0.85, 1.15)),
            "arw_urad_per_sqrt_s": round(log_uniform(rng, 0.003, 0.5), 5),
            "bias_instability_urad_per_s": round(log_uniform(rng, 0.005, 0.1), 5),
            "pickoff_noise_rms_urad": g.pickoff_noise_rms_urad * k,
            "pickoff_lines": [[f, a * k] for f, a in g.pickoff_lines],
        }
    return cfg


def truth_of(cfg: dict[str, dict[str, Any]], key: str, ch: str) -> float:
    return float(cfg[f"gyro.{ch}"][key])


def _steps(path: Path, proc: type[Procedure[Any]]) -> dict[str, Any]:
    """The steps' results the run file records, as JSON (a record's ``steps``)."""
    from procedures.resume import load_resume

    done = load_resume(path, proc, complete_ok=True)
    return {name: r.to_json() for name, r in done.results.items()}


def run_case(seed: int, keep: str | None = None, skip: tuple[str, ...] = ()) -> dict[str, Any]:
    from drivers.rig import open_rig
    from procedures.calibrations.earth_rate import EarthRate
    from procedures.calibrations.stopwatch import Stopwatch
    from procedures.runner import run_procedure

    cfg = draw_rig(seed)
    rec: dict[str, Any] = {"seed": seed, "config": cfg}
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(keep) / f"rig{seed}" if keep else Path(tmp)
        d.mkdir(parents=True, exist_ok=True)
        path = d / "rig.toml"
        path.write_text(toml_of(cfg))
        kto = {ch: truth_of(cfg, "torquer_scale_urad_per_s_per_V", ch) for ch in CHANNELS}
        for name, make in (
            ("earth-rate", lambda: EarthRate()),
            ("stopwatch", lambda: Stopwatch(Stopwatch.Params(kto_urad_per_s_per_V=kto))),
        ):
            if name in skip:
                continue
            t0 = time.perf_counter()
            try:
                proc = make()
                with open_rig(f"sim?warm=1&seed={seed}&watchdog=5&config={path}") as rig:
                    res = run_procedure(proc, rig, d, report=False)
            except Exception as e:  # reported, not fatal
                rec[name] = {"error": f"{type(e).__name__}: {e}"}
                continue
            rec[name] = {
                "wall_s": round(time.perf_counter() - t0, 1),
                "verdict": str(res.verdict),
                "values": res.values,
                "error": res.error,
                "steps": _steps(res.file, type(proc)) if res.file and res.file.exists() else None,
            }
    rec["verdict"] = " ".join(
        f"{n} {rec[n].get('verdict', rec[n].get('error'))}"
        for n in ("earth-rate", "stopwatch")
        if n in rec
    )
    return rec


def reanalyze(rec: dict[str, Any]) -> dict[str, Any]:
    """The record's figures from its steps' results by the analysis as it is now."""
    from procedures.calibrations.earth_rate import EarthRate
    from procedures.calibrations.stopwatch import Stopwatch
    from procedures.procedure import Context
    from simhw.config import from_dict
    from simhw.datasheet import rig_calibration

    sections: dict[str, Any] = {}
    for name, kv in rec["config"].items():
        head, _, sub = name.partition(".")
        (
            sections.setdefault(head, {}).setdefault(sub, {})
            if sub
            else sections.setdefault(head, {})
        ).update(kv)
    cal = rig_calibration(from_dict(sections))
    kto = {ch: truth_of(rec["config"], "torquer_scale_urad_per_s_per_V", ch) for ch in CHANNELS}
    for name, proc in (
        ("earth-rate", EarthRate()),
        ("stopwatch", Stopwatch(Stopwatch.Params(kto_urad_per_s_per_V=kto))),
    ):
        r = rec.get(name) or {}
        if not r.get("steps"):
            continue
        rig = SimpleNamespace(calibration=cal)  # all the analysis asks of the rig
        ctx = Context(proc, rig, None, progress=None, abort=threading.Event(), path=Path("-"))  # type: ignore[arg-type]
        kinds = {s.name: s.result for s in proc.plan()}
        ctx.results = {n: kinds[n].from_json(v) for n, v in r["steps"].items() if n in kinds}
        r["values"] = proc.analyze(ctx).values
    return rec


def _campaign(rec: dict[str, Any], ch: str) -> tuple[float, list[float], bool] | None:
    """K_g as the stopwatch would give it with the earth-rate K_TO and its interval."""
    er, sw = (rec.get("earth-rate") or {}).get("values"), (rec.get("stopwatch") or {}).get("values")
    if not er or not sw:
        return None
    kto_true = truth_of(rec["config"], "torquer_scale_urad_per_s_per_V", ch)
    kto_ci = er["K_TO_urad_per_s_per_V_ci95"][ch]
    kg_ci = sw["K_g_mV_per_urad_ci95"][ch]
    if None in kto_ci or None in kg_ci:
        return None
    kto = (
        0.5 * (kto_ci[0] + kto_ci[1])
        if er["K_TO_urad_per_s_per_V"][ch] is None
        else er["K_TO_urad_per_s_per_V"][ch]
    )
    kg_given = (
        0.5 * (kg_ci[0] + kg_ci[1])
        if sw["K_g_mV_per_urad"][ch] is None
        else sw["K_g_mV_per_urad"][ch]
    )
    kg = kg_given * kto_true / kto
    # the statistical half-width below the value, and what the interval adds above it (a bound)
    below = (kg_given - kg_ci[0]) / kg_given
    above = (kg_ci[1] - kg_given) / kg_given - below
    rel = math.hypot(below, (kto_ci[1] - kto_ci[0]) / 2 / kto)
    return (
        kg,
        [kg * (1 - rel), kg * (1 + rel + above)],
        bool(er["resolved"]["K_TO_urad_per_s_per_V"][ch] and sw["resolved"]["K_g_mV_per_urad"][ch]),
    )


def rows(
    recs: list[dict[str, Any]],
) -> list[tuple[str, str, list[tuple[float, list[float], bool, float]]]]:
    """(figure, channel, [(value, ci, resolved, truth)]) per figure and channel."""
    out = []
    for label, proc, key, cfg_key in (
        ("K_TO", "earth-rate", "K_TO_urad_per_s_per_V", "torquer_scale_urad_per_s_per_V"),
        ("K_g (K_TO given)", "stopwatch", "K_g_mV_per_urad", "pickoff_scale_mV_per_urad"),
    ):
        for ch in CHANNELS:
            cases = []
            for r in recs:
                v = (r.get(proc) or {}).get("values")
                if not v or ch not in v.get(f"{key}_ci95", {}):
                    continue
                ci = v[f"{key}_ci95"][ch]
                if ci[0] is None or ci[1] is None:
                    continue
                val = v[key][ch] if v[key][ch] is not None else 0.5 * (ci[0] + ci[1])
                cases.append(
                    (val, ci, bool(v["resolved"][key][ch]), truth_of(r["config"], cfg_key, ch))
                )
            out.append((label, ch, cases))
    for ch in CHANNELS:
        cases = []
        for r in recs:
            c = _campaign(r, ch)
            if c is not None:
                cases.append((*c, truth_of(r["config"], "pickoff_scale_mV_per_urad", ch)))
        out.append(("K_g (campaign)", ch, cases))
    return out


def summarize(recs: list[dict[str, Any]]) -> str:
    lines = [
        f"calibration coverage: {len(recs)} rigs; errors: "
        + "; ".join(
            f"seed {r['seed']} {n}: {(r.get(n) or {}).get('error')}"
            for r in recs
            for n in ("earth-rate", "stopwatch")
            if (r.get(n) or {}).get("error")
        )
        or "none"
    ]
    lines.append(
        f"{'figure':<18s} {'ch':<4s} {'n':>3s} {'covered':>8s} {'med |err|':>10s} {'max |err|':>10s} "
        f"{'med half':>9s} {'unresolved':>10s}  misses (seed: err, half-width, latitude)"
    )
    total_n = total_c = 0
    for label, ch, cases in rows(recs):
        seeds = [r["seed"] for r in recs]
        n = len(cases)
        if not n:
            continue
        cov = sum(ci[0] <= t <= ci[1] for _, ci, _, t in cases)
        total_n, total_c = total_n + n, total_c + cov
        err = [abs(v / t - 1) for v, _, res, t in cases if res]
        half = [(ci[1] - ci[0]) / 2 / abs(v) for v, ci, _, _ in cases]
        unres = sum(not res for *_, res, _ in [(c[0], c[1], c[2], c[3]) for c in cases])
        misses = []
        for s, (v, ci, _, t) in zip(seeds, cases):
            if not ci[0] <= t <= ci[1]:
                lat = next(r for r in recs if r["seed"] == s)["config"]["site"]["latitude_deg"]
                misses.append(
                    f"{s}: {100 * (v / t - 1):+.2f} % +-{100 * (ci[1] - ci[0]) / 2 / abs(v):.2f} lat {lat:+.0f}"
                )
        med = f"{100 * statistics.median(err):.3f} %" if err else "-"
        mx = f"{100 * max(err):.3f} %" if err else "-"
        lines.append(
            f"{label:<18s} {ch:<4s} {n:>3d} {cov:>4d}/{n:<3d} {med:>10s} {mx:>10s} "
            f"{100 * statistics.median(half):>7.3f} % {unres:>4d}/{n:<5d}  " + "; ".join(misses)
        )
    lines.append(f"all figures: {total_c}/{total_n} covered")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rigs", type=int, default=20)
    ap.add_argument("--first", type=int, default=0, help="first seed (to extend an earlier run)")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", default="/tmp/calibration_coverage.jsonl")
    ap.add_argument("--keep", default=None, help="keep each rig's run files under DIR/rig<seed>")
    ap.add_argument(
        "--also", nargs="*", default=[], help="earlier --out files to summarize with this run"
    )
    ap.add_argument(
        "--reuse",
        default=None,
        help="an earlier --out file: its seeds' earth-rate runs are analysed again, not run "
        "(only the stopwatch runs on them)",
    )
    ap.add_argument(
        "--reanalyze",
        nargs="*",
        default=None,
        help="analyse these --out files' recorded steps again (no rig runs)",
    )
    args = ap.parse_args(argv)
    if args.reanalyze is not None:
        recs = [
            reanalyze(json.loads(line))
            for f in args.reanalyze
            for line in Path(f).read_text().splitlines()
            if line.strip()
        ]
    else:
        reuse = (
            {r["seed"]: r for r in map(json.loads, Path(args.reuse).read_text().splitlines())}
            if args.reuse
            else {}
        )
        recs = run_cases(
            run_case,
            [
                (s, args.keep, ("earth-rate",) if s in reuse else ())
                for s in range(args.first, args.first + args.rigs)
            ],
            args.jobs,
            args.out,
        )
        for r in recs:
            if r["seed"] in reuse:
                r["earth-rate"] = reanalyze({**reuse[r["seed"]], "stopwatch": None})["earth-rate"]
        if reuse:
            Path(args.out).write_text("".join(json.dumps(r) + "\n" for r in recs))
        recs += [
            json.loads(line)
            for f in args.also
            for line in Path(f).read_text().splitlines()
            if line.strip()
        ]
    recs.sort(key=lambda r: r["seed"])
    print(summarize(recs))
    return 0


if __name__ == "__main__":
    sys.exit(main())
