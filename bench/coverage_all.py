"""Coverage of every figure the calibration campaign prints, on rigs drawn independently
(issue 38, acceptance A): one harness, one rig distribution, every procedure.

Each rig (``draw_rig``, seeded by ``[3840, seed]``) is a sim configuration the procedures are
never told. It runs ``fbs demo``'s campaign (``fbs.demo.run_campaign``: earth-rate, stopwatch,
hysteresis X and Y, baseline, survey, excitation in Modes 3 and 4, drift; each procedure with the
results of the ones before it, as a lab chains them) and reads the campaign's own figure table,
``figures.json``: every printed figure with its 95 % interval, whether it is resolved and the
rig's truth at the conditions measured (``fbs.demo_truth``: a parameter of the config, an exact
computation, or an offline simulation of the same rig four times the record). Rows whose truth
is a Dahl bearing's describing function (amplitude-dependent, approximate) are counted apart.

The distribution is wider than the one the procedures' tests draw (tests/procedures/*):

* site latitude uniform -70 .. +75 deg; the rotary table base's azimuth offset +-6 deg;
* platform inertia x0.7 .. 1.4 per axis; each compensation corner w1..w6 x0.9 .. 1.15;
* per axis a bearing model drawn from none / viscous / spring / dahl (To, eta, stiffness
  log-uniform x0.5 .. 2, viscous damping 0.01 .. 0.2 N m s), Z included;
* the primary autocollimator: white NEA x0.6 .. 1.6 with a common X/Y part 0 .. 0.6, its 1/f
  corner 1.5 .. 5 Hz, knee form between ``max(1, fc/f)`` and ``1 + fc/f``, slope -0.8 .. -1.2 (the
  noise is not of the shape an analysis assumes); the azimuth NEA x0.6 .. 1.6;
* per gyro channel: K_TO x0.85 .. 1.15, K_g x0.8 .. 1.2, fixed drift +-1.5 urad/s, g-drifts
  +-0.15 urad/s/g, restraint h/k x0.85 .. 1.15, ARW log-uniform 0.003 .. 0.5 urad/sqrt(s), bias
  instability log-uniform 0.005 .. 0.1 urad/s; pickoff white noise x0.5 .. 2 and each line's
  frequency +-1 Hz and amplitude x0.5 .. 2 (DESIGN section 8's nominal unit); the float's viscous
  coupling h/c x0.7 .. 1.3 (the data sheet's tolerance, which the procedures' intervals carry).

Prints per figure (a row of the campaign's table, e.g. "K_TO Z"): n, how many carry an interval,
covered (the interval holds the truth, resolved or not), median and max |relative error| of the
resolved values, the median relative half-width and the unresolved share; then the totals, all
and split into resolved figures and unresolved bounds (acceptance A asks 93-98 % of each), with
the binomial range a 95 % interval's coverage should fall in. Benchmarks report, they never fail.

A rig costs one campaign (~4.5 min of wall time on an idle core, more on a busy one) plus its
offline truths. The records are JSON lines, appended as rigs finish, so a run can be extended
(``--first``) and summarised with earlier ones (``--also``), or only summarised (``--rigs 0``).
``--keep DIR --again`` makes the tables of the kept rigs again from their summaries (a change
to the table or the truths needs no new runs), ``--reanalyse earth-rate,..`` with it analyses the
kept runs of those procedures again first (a change to their analysis needs none either).
Usage: ``python bench/coverage_all.py [--rigs 40] [--first 0] [--jobs 1] [--out F.jsonl]
[--keep DIR] [--again [--reanalyse PROC,..]] [--also F.jsonl ...]``.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import re  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from coverage_pool import draw_plant, log_uniform, run_cases, toml_of  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
CHANNELS = ("X", "Y", "Z", "XRD")


def _noise_shape(rng: np.random.Generator) -> dict[str, float]:
    """A nominal unit's autocollimator 1/f: corner, knee form and slope (DESIGN section 8)."""
    knee = 1.0 if rng.random() < 0.4 else round(float(rng.uniform(0.0, 1.0)), 3)
    return {
        "flicker_corner_hz": round(float(rng.uniform(1.5, 5.0)), 3),
        "flicker_knee": knee,
        "flicker_slope": round(float(rng.uniform(0.8, 1.2)), 3),
    }


def draw_rig(seed: int) -> dict[str, dict[str, Any]]:
    """The rig of ``seed`` as TOML sections (the module docstring's distribution)."""
    from drivers.rig_datasheet import VISCOUS_COUPLING_TOLERANCE
    from simhw.config import SimConfig

    nom = SimConfig()
    rng = np.random.default_rng([3840, seed])
    cfg: dict[str, dict[str, Any]] = {
        "site": {"latitude_deg": round(float(rng.uniform(-70.0, 75.0)), 3)},
        "table": {"base_azimuth_offset_deg": round(float(rng.uniform(-6.0, 6.0)), 4)},
    }
    cfg |= draw_plant(rng, nom)
    nea, common = float(rng.uniform(0.6, 1.6)), round(float(rng.uniform(0.0, 0.6)), 3)
    shape = _noise_shape(rng)
    for a in ("X", "Y"):
        cfg[f"autocollimator.{a}"] = {
            "nea_urad": round(nom.autocollimator[a].nea_urad * nea, 5),
            "common_noise_fraction": common,
            **shape,
        }
    cfg["azimuth"] = {"nea_urad": round(nom.azimuth.nea_urad * float(rng.uniform(0.6, 1.6)), 4)}
    for ch in CHANNELS:
        g = nom.gyro[ch]
        # the total rms is the white part's and the lines' together
        lines = [
            [round(f + float(rng.uniform(-1.0, 1.0)), 3), a * float(rng.uniform(0.5, 2.0))]
            for f, a in g.pickoff_lines
        ]
        white0 = g.pickoff_noise_rms_urad**2 - sum(a * a / 2 for _, a in g.pickoff_lines)
        white = max(white0, 0.0) * float(rng.uniform(0.5, 2.0)) ** 2
        rms = math.sqrt(white + sum(a * a / 2 for _, a in lines))
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
            "pickoff_noise_rms_urad": rms,
            "pickoff_lines": lines,
        }
    # the floats' viscous coupling h/c within the data sheet's tolerance, which the procedures
    # carry in their intervals (``VISCOUS_COUPLING_TOLERANCE``); from a stream of its own, so
    # the draws above are those of the rigs measured before it was drawn
    coupling = np.random.default_rng([3840, seed, 1])
    for ch in CHANNELS:
        cfg[f"gyro.{ch}"]["viscous_coupling_h_over_c"] = nom.gyro[ch].viscous_coupling_h_over_c * (
            float(coupling.uniform(1 - VISCOUS_COUPLING_TOLERANCE, 1 + VISCOUS_COUPLING_TOLERANCE))
        )
    return cfg


def run_case(seed: int, keep: str | None = None) -> dict[str, Any]:
    """One rig's campaign; its figure table and each run's verdict."""
    from fbs.demo import run_campaign

    cfg = draw_rig(seed)
    rec: dict[str, Any] = {"seed": seed, "config": cfg}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(keep) / f"rig{seed}" if keep else Path(tmp)
        d.mkdir(parents=True, exist_ok=True)
        path = d / "rig.toml"
        path.write_text(toml_of(cfg))
        try:
            summaries, report = run_campaign(d / "campaign", cfg_path=str(path), seed=seed)
        except Exception as e:  # reported, not fatal: the table counts the rig as an error
            rec["error"] = f"{type(e).__name__}: {e}"
            rec["wall_s"] = round(time.perf_counter() - t0, 1)
            return rec
        rec["rows"] = json.loads((report.parent / "figures.json").read_text())
        rec["runs"] = [
            {
                "procedure": s.procedure,
                "axis": s.params.get("axis"),
                "verdict": str(s.verdict),
                "status": s.status,
                "error": s.error,
            }
            for s in summaries
        ]
    rec["wall_s"] = round(time.perf_counter() - t0, 1)
    rec["verdict"] = " ".join(f"{r['procedure']}:{r['verdict']}" for r in rec["runs"])
    return rec


def reanalyse(campaign: Path, procedures: tuple[str, ...]) -> None:
    """Every kept run of ``procedures`` in ``campaign`` analysed again by the product's own path,
    ``fbs run PROC --resume FILE`` (a complete run: its analysis runs again with the earlier
    results it was made with, its summary and report are rewritten, the rig is not driven)."""
    import subprocess

    for path in sorted(campaign.glob("*.json")):
        d = json.loads(path.read_text())
        if not isinstance(d, dict) or d.get("procedure") not in procedures or not d.get("file"):
            continue
        cmd = [sys.executable, "-m", "fbs", "run", d["procedure"], "--rig", d["rig"]]
        cmd += ["--resume", d["file"], "--out", str(campaign)]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode not in (0, 1):  # 1: limits failed, still a result
            last = (done.stderr.strip().splitlines() or ["no message"])[-1]
            raise RuntimeError(f"{' '.join(cmd)}: exit {done.returncode}: {last}")


def rows_again(seed: int, keep: str, procedures: tuple[str, ...] = ()) -> dict[str, Any]:
    """A kept rig's figure table made again from its campaign's summaries (a change to the
    table or the truths, not to the procedures, needs no new run); the runs of ``procedures``
    are analysed again first (a change to their analysis needs none either, ``reanalyse``)."""
    from fbs.demo import SimTruth, figure_rows, load_summaries
    from simhw.config import load_config

    t0 = time.perf_counter()
    d = Path(keep) / f"rig{seed}"
    reanalyse(d / "campaign", procedures)
    summaries = load_summaries(d / "campaign")
    rows = figure_rows(summaries, SimTruth(load_config(d / "rig.toml"), seed))
    return {
        "seed": seed,
        "config": draw_rig(seed),
        "rows": [r.as_json() for r in rows],
        "runs": [
            {"procedure": s.procedure, "axis": s.params.get("axis"), "verdict": str(s.verdict)}
            for s in summaries
        ],
        "verdict": "rows made again",
        "wall_s": round(time.perf_counter() - t0, 1),
    }


def _rel(measured: float | None, truth: float | None) -> float | None:
    if measured is None or truth is None or truth == 0 or not math.isfinite(measured):
        return None
    return abs(measured / truth - 1.0)


def _half(row: dict[str, Any]) -> float | None:
    iv, t = row.get("interval"), row.get("truth")
    if not iv or iv[0] is None or iv[1] is None or not t:
        return None
    return abs(iv[1] - iv[0]) / 2 / abs(t)


def _pct(x: list[float]) -> str:
    return "-" if not x else f"{100 * statistics.median(x):.3g} / {100 * max(x):.3g} %"


def figure_of(quantity: str) -> str:
    """A row's figure, the same on every rig: an amplitude-dependent figure's label carries the
    run's own amplitude ("bearing stiffness at 2.1062 urad rms X")."""
    return re.sub(r" at (about )?[0-9.eE+-]+ urad rms", " at the test amplitude", quantity)


def table(recs: list[dict[str, Any]]) -> str:
    """The per-figure table and the totals (module docstring)."""
    by: dict[tuple[bool, str], list[dict[str, Any]]] = defaultdict(list)
    order: list[tuple[bool, str]] = []
    for rec in sorted(recs, key=lambda r: r["seed"]):
        for row in rec.get("rows", []):
            if row.get("truth") is None:
                continue
            key = (not row["truth_exact"], figure_of(row["quantity"]))
            if key not in by:
                order.append(key)
            by[key].append(row)
    out = [
        "| figure | n | with interval | covered | median / max error (resolved) "
        "| median half-width | unresolved |",
        "|---|---|---|---|---|---|---|",
    ]
    tot = {False: [0, 0], True: [0, 0]}
    split = {True: [0, 0], False: [0, 0]}  # exact truths: resolved figures, unresolved bounds
    for approx in (False, True):
        if approx:
            out.append(
                "| *describing-function truths (approximate, not in the totals)* | | | | | | |"
            )
        for key in (k for k in order if k[0] == approx):
            rows = by[key]
            iv = [r for r in rows if r.get("covered") is not None]
            cov = sum(bool(r["covered"]) for r in iv)
            tot[approx][0] += len(iv)
            tot[approx][1] += cov
            if not approx:
                for r in iv:
                    split[bool(r.get("resolved"))][0] += 1
                    split[bool(r.get("resolved"))][1] += bool(r["covered"])
            errs = [
                e
                for r in rows
                if r.get("resolved") is not False
                for e in [_rel(r.get("measured"), r["truth"])]
                if e is not None
            ]
            halves = [h for r in iv for h in [_half(r)] if h is not None]
            unres = sum(r.get("resolved") is False for r in rows)
            out.append(
                f"| {key[1]} | {len(rows)} | {len(iv)} | {cov}/{len(iv)} | {_pct(errs)} | "
                f"{'-' if not halves else f'{100 * statistics.median(halves):.3g} %'} | "
                f"{unres}/{len(rows)} |"
            )
    n, k = tot[False]
    lo, hi = _binomial_range(n)
    errors = [r for r in recs if "error" in r]
    out += [
        "",
        f"rigs: {len(recs)} ({len(errors)} ended in an error"
        + (": " + "; ".join(f"seed {r['seed']}: {r['error']}" for r in errors) if errors else "")
        + ")",
        f"figures with an interval and an exact truth: {n}, covered {k}"
        + (
            f" ({100 * k / n:.1f} %; of {n} right 95 % intervals, {lo}..{hi} cover, 99 % of the time)"
            if n
            else ""
        ),
        *(
            f"  {what}: {m}, covered {c} ({100 * c / m:.2f} %; {_binomial_range(m)[0]}.."
            f"{_binomial_range(m)[1]} for right 95 % intervals)"
            for what, (m, c) in (
                ("resolved figures", split[True]),
                ("unresolved bounds", split[False]),
            )
            if m
        ),
        f"describing-function rows: {tot[True][0]}, covered {tot[True][1]}",
    ]
    return "\n".join(out)


def _binomial_range(n: int, p: float = 0.95) -> tuple[int, int]:
    """The central 99 % range of the count covered among ``n`` right 95 % intervals."""
    from scipy.stats import binom

    if n == 0:
        return 0, 0
    return int(binom.ppf(0.005, n, p)), int(binom.ppf(0.995, n, p))


def misses(recs: list[dict[str, Any]]) -> str:
    """Every figure whose interval excludes its exact truth, with its rig."""
    out = []
    for rec in sorted(recs, key=lambda r: r["seed"]):
        for row in rec.get("rows", []):
            if row.get("covered") is False and row.get("truth_exact"):
                out.append(
                    f"seed {rec['seed']}: {row['quantity']}: {row['measured']} {row['interval']} "
                    f"({'resolved' if row['resolved'] is not False else 'unresolved'}) "
                    f"truth {row['truth']} ({row['truth_kind']})"
                )
    return "\n".join(out)


def _read(paths: list[str]) -> list[dict[str, Any]]:
    recs: dict[int, dict[str, Any]] = {}
    for p in paths:
        if Path(p).exists():
            for line in Path(p).read_text().splitlines():
                if line.strip():
                    rec = json.loads(line)
                    recs[rec["seed"]] = rec  # the latest record of a seed
    return list(recs.values())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rigs", type=int, default=40)
    ap.add_argument("--first", type=int, default=0, help="first seed (to extend an earlier run)")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", default="/tmp/coverage_all.jsonl")
    ap.add_argument("--keep", default=None, help="keep each rig's campaign under DIR/rig<seed>")
    ap.add_argument("--also", nargs="*", default=[], help="earlier --out files to summarise too")
    ap.add_argument(
        "--again",
        action="store_true",
        help="make the figure tables of the rigs kept under --keep again (no new runs)",
    )
    ap.add_argument(
        "--reanalyse",
        default="",
        metavar="PROC,..",
        help="with --again: analyse the kept runs of these procedures again first",
    )
    args = ap.parse_args(argv)
    t0 = time.monotonic()
    recs = []
    if args.again:
        done = Path(args.keep).glob("rig*/campaign/figures.json")  # finished campaigns only
        seeds = sorted(int(p.parent.parent.name[3:]) for p in done)
        procs = tuple(p for p in args.reanalyse.split(",") if p)
        cases = [(s, args.keep, procs) for s in seeds]
        recs = run_cases(rows_again, cases, args.jobs, args.out)
    elif args.rigs > 0:
        cases = [(s, args.keep) for s in range(args.first, args.first + args.rigs)]
        recs = run_cases(run_case, cases, args.jobs, args.out)
    recs = _read(args.also) + recs
    seen = {r["seed"]: r for r in recs}
    recs = list(seen.values())
    print(table(recs))
    m = misses(recs)
    if m:
        print("\nintervals that exclude the truth:\n" + m)
    print(f"\nbench wall time {time.monotonic() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
