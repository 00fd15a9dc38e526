"""Coverage of the drift procedure's 95 % intervals for the gyro's own N and B (issue 18, acceptance D).

Two parts:

* **synthetic** (seconds): 2 h at 10 Hz of white angle noise (the pickoff's, differentiated, as in
  a reconstructed input rate) + white rate N + flicker rate B (Kasdin-Walter), analysed by
  ``allan.fit_noise_model`` and ``allan.term_estimate``: (a) angle 0.01 urad, N 0.03, B 0.02 (both
  terms visible), (b) angle 0.6 urad, N 0.005, B 0.02 (the sim's pickoff noise: N hidden).
* **sim** (about 10 s of wall time per 40-min run): ``fbs run drift`` on the sim rig in virtual
  time, default configuration (N 0.005, B 0.02 urad/s), B tripled (0.06), and N raised to 0.3;
  every channel's ``K_ci95`` is checked against the sim's parameter, resolved or not.

Reported per case and figure: how often the interval held the truth, how often it was resolved,
and for the resolved ones the median relative error. Benchmarks report, they never fail.
Usage: ``python bench/drift_coverage.py [--seeds 6] [--synthetic 30] [--duration 2400] [--out F.jsonl]``.
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
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

log = logging.getLogger("drift_coverage")
CHANNELS = ("X", "Y", "Z", "XRD")
FS = 10.0
KEYS = {"arw": "arw_urad_per_sqrt_s", "bias": "bias_instability_urad_per_s"}
#: sim cases: name -> (gyro parameters set on every channel, the truth per figure)
SIM_CASES: dict[str, tuple[dict[str, float], dict[str, float]]] = {
    "default": ({}, {"arw": 0.005, "bias": 0.02}),
    "B x3": ({"bias_instability_urad_per_s": 0.06}, {"arw": 0.005, "bias": 0.06}),
    "N 0.3": ({"arw_urad_per_sqrt_s": 0.3}, {"arw": 0.3, "bias": 0.02}),
}


def flicker_rate(rng: np.random.Generator, n: int, B: float) -> np.ndarray:
    """Flicker rate noise of one-sided PSD B^2 / (pi f) (Kasdin and Walter 1992)."""
    w = np.zeros(2 * n)
    w[:n] = rng.standard_normal(n) * B
    h = np.zeros(2 * n)
    k = np.arange(1, n)
    h[0] = 1.0
    h[1:n] = np.cumprod((k - 0.5) / k)
    return np.fft.irfft(np.fft.rfft(w) * np.fft.rfft(h))[:n]


def synthetic_case(seed: int, angle_urad: float, N: float, B: float, n: int = 72000) -> dict[str, Any]:
    from procedures.analysis import allan
    from procedures.analysis.intervals import judged

    rng = np.random.default_rng(seed)
    y = (np.diff(rng.standard_normal(n + 1) * angle_urad) * FS + rng.standard_normal(n) * N * math.sqrt(FS)
         + flicker_rate(rng, n, B))
    res = allan.allan_deviation(y, FS)
    model = allan.fit_noise_model(res, min_tau_s=0.2)
    out: dict[str, Any] = {}
    for term, truth in (("arw", N), ("bias", B)):
        t = allan.term_estimate(res, model, term, min_tau_s=0.2)
        resolved = math.isfinite(t.value) and judged(t.value, t.lo, t.hi).resolved
        out[term] = {"value": t.value if resolved else None, "ci": [t.lo, t.hi], "resolved": resolved,
                     "covered": t.lo <= truth <= t.hi, "truth": truth}
    return out


def sim_case(name: str, seed: int, duration_s: float) -> dict[str, Any]:
    from drivers.rig import open_rig
    from procedures.calibrations.drift import Drift
    from procedures.runner import run_procedure

    params, truth = SIM_CASES[name]
    rec: dict[str, Any] = {"case": name, "seed": seed, "duration_s": duration_s}
    with tempfile.TemporaryDirectory() as d:
        cfg = Path(d) / "rig.toml"
        cfg.write_text("".join(f"[gyro.{c}]\n" + "".join(f"{k} = {v}\n" for k, v in params.items())
                               for c in CHANNELS))
        t0 = time.perf_counter()
        try:
            with open_rig(f"sim?warm=1&seed={seed}&watchdog=5&config={cfg}") as rig:
                s = run_procedure(Drift(Drift.Params(duration_s=duration_s, n_chunks=2)), rig, Path(d))
        except Exception as e:  # reported, not fatal
            rec["error"] = f"{type(e).__name__}: {e}"
            return rec
        rec["wall_s"] = round(time.perf_counter() - t0, 1)
        rec["exit_code"] = s.exit_code
        for term, key in KEYS.items():
            ci, ok = s.values[f"{key}_ci95"], s.values["resolved"][key]
            rec[term] = {ch: {"value": s.values[key][ch], "ci": ci[ch], "resolved": ok[ch], "truth": truth[term],
                              "covered": ci[ch][0] is not None and ci[ch][1] is not None
                              and ci[ch][0] <= truth[term] <= ci[ch][1]} for ch in CHANNELS}
    return rec


def _row(label: str, items: list[dict[str, Any]]) -> str:
    n = len(items)
    cov = sum(bool(i["covered"]) for i in items)
    res = [i for i in items if i["resolved"]]
    err = [abs(i["value"] / i["truth"] - 1) for i in res if i["value"] is not None]
    med = f"{100 * statistics.median(err):.0f} %" if err else "-"
    widths = [i["ci"][1] for i in items if not i["resolved"] and i["ci"][1] is not None]
    bound = f"{statistics.median(widths):.3g}" if widths else "-"
    return f"{label:<34s} {cov:>3d}/{n:<3d} {len(res):>4d}/{n:<3d} {med:>10s} {bound:>12s}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=6, help="sim runs per case")
    ap.add_argument("--synthetic", type=int, default=30, help="synthetic records per case")
    ap.add_argument("--duration", type=float, default=2400.0, help="sim record length (s)")
    ap.add_argument("--cases", default=",".join(SIM_CASES), help="sim cases, comma separated")
    ap.add_argument("--out", type=Path, help="JSON lines of every run")
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    logging.getLogger("drivers").setLevel(logging.CRITICAL)   # the rig's own fault log under load
    lines = [f"{'case / figure [channel]':<34s} {'covered':>7s} {'resolved':>8s} {'med |err|':>10s} "
             f"{'med bound':>12s}"]
    for label, angle, N, B in (("synthetic a: angle 0.01, N 0.03", 0.01, 0.03, 0.02),
                               ("synthetic b: angle 0.6, N 0.005", 0.6, 0.005, 0.02)):
        recs = [synthetic_case(seed, angle, N, B) for seed in range(1, args.synthetic + 1)]
        for term in KEYS:
            lines.append(_row(f"{label} {term}", [r[term] for r in recs]))
    out = args.out.open("w") if args.out else None
    for name in args.cases.split(","):
        recs = []
        for seed in range(1, args.seeds + 1):
            rec = sim_case(name, seed, args.duration)
            log.info("%s seed %d: %s", name, seed, rec.get("error") or f"exit {rec['exit_code']}, {rec['wall_s']} s")
            if out:
                out.write(json.dumps(rec) + "\n")
            if "error" not in rec:
                recs.append(rec)
        for term in KEYS:
            for ch in CHANNELS:
                lines.append(_row(f"sim {name} {args.duration:g} s {term} [{ch}]", [r[term][ch] for r in recs]))
            lines.append(_row(f"sim {name} {args.duration:g} s {term} [all]",
                              [r[term][ch] for r in recs for ch in CHANNELS]))
    if out:
        out.close()
    sys.stdout.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
