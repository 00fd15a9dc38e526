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

The rules live in ``tests/procedures/analysis/gap/devset_rules.py`` (shared with the test).
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
import importlib.util  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
DEVSET = ROOT / "tests" / "data" / "gapdata"
RULES = ROOT / "tests" / "procedures" / "analysis" / "gap" / "devset_rules.py"


def _rules():
    """The set's scoring rules (a module of the test suite, loaded by path)."""
    mod = sys.modules.get("fbs_tests_gap_devset_rules")
    if mod is None:
        spec = importlib.util.spec_from_file_location("fbs_tests_gap_devset_rules", RULES)
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        sys.modules["fbs_tests_gap_devset_rules"] = mod
        spec.loader.exec_module(mod)
    return mod


def run_one(name: str) -> dict[str, Any]:
    from procedures.analysis.gap.workflow import analyse

    t0 = time.perf_counter()
    try:
        res = analyse(DEVSET / name).to_json()
    except Exception as e:  # a broken case is reported, not fatal
        return {
            "file": name,
            "error": f"{type(e).__name__}: {e}",
            "seconds": time.perf_counter() - t0,
        }
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
            ok, why, cov = _rules().score(t, o["result"])
            right += ok
            covered += cov
            print(
                f"{o['file']} {t['axis']} {label:32s} {'right' if ok else 'WRONG'}  {why}  "
                f"({o['seconds']:.1f} s)",
                flush=True,
            )
    print(
        f"dev set: {right}/{len(outs)} right; key 95 % intervals cover the truth "
        f"{sum(covered)}/{len(covered)}; seconds per file median {statistics.median(times):.1f}, "
        f"max {max(times):.1f}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
