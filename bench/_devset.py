"""The model-gap workflow on the development set of another team's simulator (issue 34, E).

Twelve files written by an independent simulator of the DESIGN.md plant, with their truth
(``tests/data/gapdata/``: ``truth.json`` and a README describing each case). Each file is
analysed by ``procedures.analysis.gap.workflow.analyse`` with its default options and scored by
the set's own rules (its README, "How an answer is scored"):

* a null is right when ``significant`` is false;
* a single catalogue effect is right when it is named first and nothing else is, its key
  parameter within 15 % (``freq_hz`` 5 %, ``corner_hz`` 30 %; a pickup line's amplitude 15 %
  and frequency 5 %);
* a file with several effects is right when all are named, nothing else is, each key within its
  tolerance;
* an effect outside the catalogue is right when ``significant`` and not ``explained``.

Also reported: whether each named key parameter's 95 % interval covers the truth, and the time
per file. Benchmarks report, they never fail: the exit code is 0 unless the bench itself breaks.
``bench/gap.py`` (in ``make bench``) runs it; alone:
``python bench/_devset.py [--jobs 2] [--files g01,g05] [--out FILE.jsonl]``.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # before numpy: the workers run one thread each

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
DEVSET = ROOT / "tests" / "data" / "gapdata"

#: the key parameters the set's README scores, and their relative tolerances
KEYS: dict[str, dict[str, float]] = {
    "bearing_friction": {"stiffness_Nm_per_rad": 0.15},
    "mount_resonance": {"freq_hz": 0.05},
    "pickup_line": {"freq_hz": 0.05, "amplitude_V": 0.15},
    "flicker_noise": {"corner_hz": 0.30},
    "offset_jumps": {"amplitude_urad": 0.15},
    "time_delay": {"delay_s": 0.15},
    "extra_damping": {"damping_Nms": 0.15},
    "scale_factor_error": {"fraction": 0.15},
}


def truth_effects(t: dict[str, Any]) -> dict[str, dict[str, float]]:
    """{effect: its true parameters} of one truth entry ({} for a null or an unknown)."""
    if "effects" in t:
        return {e: t["by_effect"][e] for e in t["effects"]}
    if t["effect"] in ("none", "unknown"):
        return {}
    return {t["effect"]: {k: v for k, v in t.items() if isinstance(v, (int, float))}}


def score(t: dict[str, Any], res: dict[str, Any]) -> tuple[bool, str, list[bool]]:
    """(right, why, interval coverage of each scored key) for one file's JSON result."""
    named = [e["effect"] for e in res["effects"]]
    if t["effect"] == "none":
        return (not res["significant"], f"significant={res['significant']} named={named}", [])
    if t["effect"] == "unknown":
        ok = res["significant"] and not res["explained"]
        return ok, f"significant={res['significant']} explained={res['explained']} named={named}", []
    want = truth_effects(t)
    covers: list[bool] = []
    why = []
    ok = sorted(named) == sorted(want)
    if len(want) == 1 and named and named[0] != next(iter(want)):
        ok = False
    for e in res["effects"]:
        true = want.get(e["effect"])
        if true is None:
            continue
        for k, tol in KEYS.get(e["effect"], {}).items():
            if k not in true or k not in e["parameters"] or e["parameters"][k] is None:
                continue
            est = e["parameters"][k]
            rel = est / true[k] - 1
            why.append(f"{e['effect']}.{k} {est:.4g} ({rel:+.1%})")
            ok = ok and abs(rel) <= tol
            iv = e.get("parameters_ci95", {}).get(k)
            if iv and None not in iv:
                covers.append(iv[0] <= true[k] <= iv[1])
                why[-1] += f" [{iv[0]:.4g}, {iv[1]:.4g}]"
    return ok, f"named={named} " + "; ".join(why), covers


def run_one(name: str) -> dict[str, Any]:
    from procedures.analysis.gap.workflow import analyse

    t0 = time.perf_counter()
    try:
        res = analyse(DEVSET / name).to_json()
    except Exception as e:  # a broken case is reported, not fatal
        return {"file": name, "error": f"{type(e).__name__}: {e}", "seconds": time.perf_counter() - t0}
    return {"file": name, "result": res, "seconds": time.perf_counter() - t0}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--files", default="", help="comma-separated stems (g01,g05); default all")
    ap.add_argument("--out", default="/tmp/gap_devset.jsonl")
    a = ap.parse_args(argv)
    truth = json.loads((DEVSET / "truth.json").read_text())
    names = sorted(truth)
    if a.files:
        stems = {s.strip() for s in a.files.split(",")}
        names = [n for n in names if Path(n).stem in stems]
    with ProcessPoolExecutor(a.jobs) as pool:
        outs = list(pool.map(run_one, names))
    right, covered, times = 0, [], []
    with open(a.out, "w") as fh:
        for o in outs:
            fh.write(json.dumps(o) + "\n")
            t = truth[o["file"]]
            label = t["effect"] if "effects" not in t else "+".join(t["effects"])
            times.append(o["seconds"])
            if "error" in o:
                print(f"{o['file']} {t['axis']} {label:32s} ERROR {o['error']}")
                continue
            ok, why, cov = score(t, o["result"])
            right += ok
            covered += cov
            print(f"{o['file']} {t['axis']} {label:32s} {'right' if ok else 'WRONG'}  {why}  "
                  f"({o['seconds']:.1f} s)", flush=True)
    print(f"dev set: {right}/{len(outs)} right; key 95 % intervals cover the truth "
          f"{sum(covered)}/{len(covered)}; seconds per file median {statistics.median(times):.1f}, "
          f"max {max(times):.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
