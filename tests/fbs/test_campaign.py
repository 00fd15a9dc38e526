"""``fbs campaign gap`` (issue 23 part 2): detection curves of the model-gap workflow over an
effect's parameter grid and seeds, on ``fbs batch``'s executors.

Proved here, with real processes throughout:
- the campaign writes runs.jsonl (one line per run), curves.json (= ``--json``), curves.md and
  curves.png; the effect is named where it should be, with its amplitude recovered;
- B: the same campaign on a real Dask cluster (``dask scheduler`` + two ``dask worker``
  processes on localhost, the ``cluster`` fixture of conftest.py) gives the same runs.jsonl
  results as the local pool (same seeds, same records, same results);
- C: a local pool worker SIGKILLed mid-campaign, or a Dask worker, loses no finished run and the
  campaign completes; a campaign interrupted (SIGTERM) keeps its runs and a re-run completes what
  is missing without redoing finished runs (and retries a run whose line is an error);
- every bad argument is refused with exit 2 before anything is written;
- units: the grid (hypothesis), the Wilson interval, the curves of synthetic runs, the record
  (the detection-limit suite's own, sample for sample).

The records are 74 s (the shortest the gap workflow analyses at 1 kHz: 73.728 s); a run costs
about 10-25 s of CPU. The campaigns here reuse runs: each smaller campaign's runs are a subset of
the reference campaign's (2 amplitudes x 2 seeds + 2 nulls), so results are compared run by run.
Timeouts are hang guards, never timing assertions.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fbs import campaign, campaign_plan, campaign_task
from fbs.campaign_plan import CampaignError, parse_grid, plan_of
from fbs.cli import build_parser, main
from procedures.analysis.gap.detection import wilson
from simhw import effects
from tests.fbs.commands import FBS

HANG_S = 900  # a hang guard for a whole campaign on a loaded machine, not a timing assertion
DURATION = "74"
EFFECT = ["gap", "--effect", "pickup_line", "--duration", DURATION]
REFERENCE = [*EFFECT, "--grid", "amplitude_V=0.0001:0.002:2", "--seeds", "2"]
#: a subset of the reference's runs: the larger amplitude, both seeds, both nulls
SUBSET = [*EFFECT, "--grid", "amplitude_V=0.002:0.002:1", "--seeds", "2"]
GAP_TESTS = Path(__file__).resolve().parents[1] / "procedures" / "analysis" / "gap"


def fbs(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*FBS, *args], capture_output=True, text=True, timeout=HANG_S)


def lines_of(path: Path) -> list[dict]:
    return [json.loads(ln) for ln in path.read_text().splitlines()]


def key(rec: dict) -> tuple:
    return rec["effect"], tuple(sorted(rec["params"].items())), rec["seed"]


def by_run(recs: list[dict]) -> dict[tuple, dict]:
    """Each run's line without its elapsed time; a run with two lines is a failure."""
    out = {key(r): {k: v for k, v in r.items() if k != "elapsed_s"} for r in recs}
    assert len(out) == len(recs), "a run has more than one line"
    return out


def wait_for_lines(path: Path, p: subprocess.Popen, n: int = 1) -> None:
    t_end = time.monotonic() + HANG_S
    while time.monotonic() < t_end:
        if path.exists() and path.read_bytes().count(b"\n") >= n:
            return
        if p.poll() is not None:
            raise AssertionError(
                f"the campaign ended (exit {p.returncode}) before {n} run(s): {p.stderr.read()}"
            )
        time.sleep(0.1)
    raise AssertionError(f"no run in {path} after {HANG_S} s")


def children(pid: int) -> list[int]:
    """The child processes of ``pid`` (Linux /proc)."""
    out = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            out += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            pass
    return out


def pool_workers(pid: int) -> list[int]:
    """The local pool's worker processes of the campaign ``pid`` (spawned: ``spawn_main``)."""
    found = []
    for c in children(pid):
        try:
            if b"spawn_main" in Path(f"/proc/{c}/cmdline").read_bytes():
                found.append(c)
        except OSError:
            pass
    return found


# ---------------------------------------------------------------------------- the reference campaign (local pool)
@pytest.fixture(scope="module")
def local(tmp_path_factory) -> tuple[subprocess.CompletedProcess[str], Path]:
    out = tmp_path_factory.mktemp("local") / "campaign"
    return fbs("campaign", *REFERENCE, "--jobs", "2", "--out", str(out), "--json"), out


@pytest.fixture(scope="module")
def reference(local) -> dict[tuple, dict]:
    r, out = local
    assert r.returncode == 0, r.stderr
    return by_run(lines_of(out / "runs.jsonl"))


@pytest.mark.slow
def test_a_campaign_writes_its_runs_and_curves(local, reference):
    r, out = local
    assert len(reference) == 6  # 2 values x 2 seeds + 2 nulls
    assert {(k[0], k[2]) for k in reference} == {
        (e, s) for e in ("none", "pickup_line") for s in (1, 2)
    }
    for rec in reference.values():
        assert list(rec) == [k for k in campaign_task.RUN_KEYS if k != "elapsed_s"]
        assert rec["record"] == {"duration_s": 74.0, "rate_hz": 1000.0, "mode": 3, "axis": "X"}
        assert rec["exit"] == 0 and rec["error"] is None
        if rec["effect"] == "none":
            assert rec["grid"] is None and rec["params"] == {}
        else:
            assert rec["grid"] == "amplitude_V" and rec["params"]["freq_hz"] == 200.0
    for seed in (1, 2):
        big = reference[("pickup_line", (("amplitude_V", 0.002), ("freq_hz", 200.0)), seed)]
        assert big["named"][:1] == ["pickup_line"] and big["significant"]
        assert big["fitted"]["amplitude_V"] == pytest.approx(0.002, rel=0.15)
        assert big["fitted"]["freq_hz"] == pytest.approx(200.0, rel=0.01)

    cv = json.loads((out / "curves.json").read_text())
    assert json.loads(r.stdout) == cv  # --json prints the curves
    assert cv["complete"] and cv["runs"] == cv["done"] == 6 and cv["errors"] == 0
    assert [pt["value"] for pt in cv["curve"]] == [0.0001, 0.002]
    top = cv["curve"][1]
    assert top["analysed"] == 2 and top["named_right"] == 2 and top["p_named"] == 1.0
    assert top["p_named_ci95"] == pytest.approx(list(wilson(2, 2)))
    assert (
        top["param_error"]["amplitude_V"]["n"] == 2
        and abs(top["param_error"]["amplitude_V"]["median"]) < 0.15
    )
    assert cv["nulls"]["analysed"] == 2 and cv["nulls"]["false_alarms"] == sum(
        1 for k, v in reference.items() if k[0] == "none" and (v["significant"] or v["named"])
    )
    assert cv["campaign"]["command"].startswith(
        "fbs campaign gap --effect pickup_line --grid "
        "amplitude_V=0.0001:0.002:2 --seeds 2 --duration 74 --out "
    )
    md = (out / "curves.md").read_text()
    assert (
        "| `amplitude_V` | runs | named right | P | 95 % |" in md
        and "| 0.002 | 2 | 2 | 1.00 |" in md
    )
    assert "False alarms on the null runs" in md
    assert (out / "curves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (
        "6 run(s) (2 value(s) x 2 seed(s) + 2 null)" in r.stderr
        and "[6/6]" in r.stderr
        and "exit 0" in r.stderr
    )


# ---------------------------------------------------------------------------- B: a Dask cluster on localhost
@pytest.mark.slow
def test_b_a_dask_cluster_gives_the_local_results(local, reference, cluster, tmp_path):
    out = tmp_path / "campaign"
    r = fbs("campaign", *REFERENCE, "--scheduler", cluster.address, "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert f"Dask scheduler {cluster.address} (2 workers, 2 threads)" in r.stderr
    assert by_run(lines_of(out / "runs.jsonl")) == reference
    mine, theirs = (json.loads((d / "curves.json").read_text()) for d in (out, local[1]))
    assert mine["curve"] == theirs["curve"] and mine["nulls"] == theirs["nulls"]


# ---------------------------------------------------------------------------- C: workers killed, campaigns interrupted
def _subset(reference: dict[tuple, dict]) -> dict[tuple, dict]:
    return {
        k: v for k, v in reference.items() if k[0] == "none" or dict(k[1])["amplitude_V"] == 0.002
    }


@pytest.mark.slow
def test_c_a_local_worker_killed_mid_campaign_loses_nothing(reference, tmp_path):
    out = tmp_path / "campaign"
    runs = out / "runs.jsonl"
    with subprocess.Popen(
        [*FBS, "campaign", *SUBSET, "--jobs", "2", "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    ) as p:
        try:
            wait_for_lines(runs, p)
            kept = runs.read_bytes()
            workers = pool_workers(p.pid)
            assert workers, "no pool worker found"
            os.kill(
                workers[0], signal.SIGKILL
            )  # a worker this test's campaign spawned, without warning
            _, err = p.communicate(timeout=HANG_S)
        finally:
            p.kill()
    assert p.returncode == 0, err
    assert "its worker process died" in err and "submitted again" in err
    assert runs.read_bytes().startswith(kept)  # nothing finished was lost or rewritten
    assert by_run(lines_of(runs)) == _subset(reference)  # each run once, the same results


@pytest.mark.slow
def test_c_a_dask_worker_killed_mid_campaign_loses_nothing(reference, cluster, tmp_path):
    out = tmp_path / "campaign"
    runs = out / "runs.jsonl"
    with subprocess.Popen(
        [*FBS, "campaign", *SUBSET, "--scheduler", cluster.address, "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    ) as p:
        try:
            wait_for_lines(runs, p)
            kept = runs.read_bytes()
            cluster.kill(cluster.workers[0])  # the worker and its nanny, without warning
            _, err = p.communicate(timeout=HANG_S)
        finally:
            p.kill()
    assert p.returncode == 0, err
    assert runs.read_bytes().startswith(kept)
    assert by_run(lines_of(runs)) == _subset(reference)
    assert cluster.n_workers() == 1


@pytest.mark.slow
def test_c_an_interrupted_campaign_keeps_its_runs_and_a_rerun_completes_it(reference, tmp_path):
    out = tmp_path / "campaign"
    runs = out / "runs.jsonl"
    # four runs one after another: when the first line is there, three are still to come, so the
    # SIGTERM lands mid-campaign however fast a run is (how many finished before it, it may vary)
    argv = [*FBS, "campaign", *SUBSET, "--jobs", "1", "--out", str(out)]
    with subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as p:
        try:
            wait_for_lines(runs, p)
            p.send_signal(signal.SIGTERM)
            _, err = p.communicate(timeout=HANG_S)
        finally:
            p.kill()
    assert p.returncode == 2 and "interrupted" in err, err
    kept = runs.read_bytes()
    done = kept.count(b"\n")
    assert 1 <= done < 4 and kept.endswith(b"\n")
    nulls = sum(r["effect"] == "none" for r in lines_of(runs))
    cv = json.loads((out / "curves.json").read_text())  # the curves of what was done
    assert cv["complete"] is False and cv["done"] == done and cv["nulls"]["done"] == nulls

    r = fbs(*argv[3:])
    assert r.returncode == 0, r.stderr
    assert f"{done} already done" in r.stderr and f"{4 - done} to run" in r.stderr
    assert runs.read_bytes().startswith(kept)
    assert by_run(lines_of(runs)) == _subset(reference)
    assert json.loads((out / "curves.json").read_text())["complete"] is True


@pytest.mark.slow
def test_c_a_rerun_skips_finished_runs_retries_errors_and_drops_a_torn_line(reference, tmp_path):
    out = tmp_path / "campaign"
    out.mkdir()
    runs = out / "runs.jsonl"
    subset = _subset(reference)
    nulls = [v for k, v in subset.items() if k[0] == "none"]
    failed = dict(subset[next(k for k in subset if k[0] != "none" and k[2] == 1)])
    failed |= {
        "exit": 2,
        "error": "its worker process died (BrokenProcessPool: ...)",
        "named": [],
        "fitted": {},
    }
    head = "".join(json.dumps(r | {"elapsed_s": 1.0}) + "\n" for r in [*nulls, failed]).encode()
    runs.write_bytes(head + b'{"effect": "pickup_l')  # a writer killed mid-line
    r = fbs("campaign", *SUBSET, "--jobs", "2", "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert "dropped an unfinished last line" in r.stderr
    assert (
        "2 already done" in r.stderr
        and "1 earlier error(s) retried" in r.stderr
        and "2 to run" in r.stderr
    )
    assert runs.read_bytes().startswith(head)
    recs = lines_of(runs)
    assert len(recs) == 5  # 3 given + 2 run
    newest = {key(rec): {k: v for k, v in rec.items() if k != "elapsed_s"} for rec in recs}
    assert newest == subset

    again = fbs("campaign", *SUBSET, "--out", str(out))
    assert again.returncode == 0 and "nothing to run" in again.stderr
    assert len(lines_of(runs)) == 5


# ---------------------------------------------------------------------------- bad inputs
def _refused(capsys, argv: list[str]) -> str:
    assert main(["campaign", *argv]) == 2
    return capsys.readouterr().err


OTHER_RUN = {
    "effect": "bearing_friction",
    "grid": "stiffness_Nm_per_rad",
    "params": {"stiffness_Nm_per_rad": 410.0, "To_Nm": 0.016, "eta_per_Nm": 1.6e6},
    "seed": 1,
    "record": {"duration_s": 74.0, "rate_hz": 1000.0, "mode": 3, "axis": "X"},
    "exit": 0,
    "named": [],
    "significant": False,
    "explained": True,
    "fitted": {},
    "fitted_ci95": {},
    "gap_before_db": 0.0,
    "gap_after_db": 0.0,
    "warnings": [],
    "error": None,
    "elapsed_s": 1.0,
}
NULL_300 = OTHER_RUN | {
    "effect": "none",
    "grid": None,
    "params": {},
    "record": OTHER_RUN["record"] | {"duration_s": 300.0},
}

BAD = {
    "workflow": (["gapp", "--effect", "pickup_line"], "unknown workflow 'gapp'"),
    "effect": (
        ["gap", "--effect", "pickup"],
        "unknown effect 'pickup'; the catalogue: bearing_friction, ",
    ),
    "effect-none": (["gap", "--effect", "none"], "--effect none has nothing to detect"),
    "grid-form": (["gap", "--grid", "amplitude_V=0.001:0.002"], "expected PARAM=LO:HI:N"),
    "grid-param": (
        ["gap", "--grid", "amp=0.001:0.002:3"],
        "pickup_line has no parameter 'amp'; its parameters: freq_hz (1..450, default 200), amplitude_V",
    ),
    "grid-nan": (["gap", "--grid", "amplitude_V=nan:0.002:3"], "LO 'nan' is not a finite number"),
    "grid-inf": (["gap", "--grid", "amplitude_V=0.001:inf:3"], "HI 'inf' is not a finite number"),
    "grid-word": (["gap", "--grid", "amplitude_V=0.001:two:3"], "HI 'two' is not a number"),
    "grid-n0": (["gap", "--grid", "amplitude_V=0.001:0.002:0"], "N '0' must be 1 to 1000"),
    "grid-n-frac": (
        ["gap", "--grid", "amplitude_V=0.001:0.002:2.5"],
        "N '2.5' is not a whole number",
    ),
    "grid-n1": (["gap", "--grid", "amplitude_V=0.001:0.002:1"], "N = 1 is one value"),
    "grid-order": (["gap", "--grid", "amplitude_V=0.002:0.001:3"], "LO must be below HI"),
    "grid-range": (
        ["gap", "--grid", "amplitude_V=0.001:0.5:3"],
        "amplitude_V = 0.5 is outside the effect's range",
    ),
    "grid-log": (
        ["gap", "--effect", "scale_factor_error", "--grid", "fraction=-0.1:0.5:3", "--log"],
        "LO must be above 0",
    ),
    "set-unknown": (["gap", "--set", "freq=50"], "pickup_line has no parameter 'freq'"),
    "set-grid": (["gap", "--set", "amplitude_V=0.001"], "amplitude_V is the --grid parameter"),
    "set-range": (
        ["gap", "--set", "freq_hz=900"],
        "freq_hz = 900 is outside the effect's range 1..450",
    ),
    "set-twice": (["gap", "--set", "freq_hz=50,freq_hz=60"], "freq_hz is set twice"),
    "set-form": (["gap", "--set", "freq_hz"], "--set 'freq_hz': expected PARAM=VALUE"),
    "seeds-0": (["gap", "--seeds", "0"], "--seeds '0' must be 1 to 10000"),
    "seeds-word": (["gap", "--seeds", "two"], "--seeds 'two' is not a whole number"),
    "duration-short": (["gap", "--duration", "60"], "--duration '60' must be 73.728 to 3600 s"),
    "duration-nan": (["gap", "--duration", "nan"], "--duration 'nan' is not a finite number"),
    "jobs-0": (["gap", "--jobs", "0"], "--jobs '0' must be at least 1"),
    "out-file": (["gap"], "is not a directory"),
    "out-missing-parent": (["gap"], "does not exist"),
    "out-not-runs": (["gap"], "is not a campaign's runs file (line 1 is not JSON)"),
    "out-other-effect": (
        ["gap"],
        "holds runs of another campaign (line 1: bearing_friction over stiffness_Nm_per_rad",
    ),
    "out-other-record": (
        ["gap"],
        "holds runs of another campaign (line 1: a null run, 300.0 s at 1000.0 Hz",
    ),
    "out-other-fixed": (
        ["gap", "--set", "freq_hz=50"],
        "holds runs of another campaign (line 1: pickup_line over amplitude_V at freq_hz = 200.0",
    ),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_inputs_are_refused_before_anything_is_written(tmp_path, capsys, case):
    out = tmp_path / "camp"
    argv, named = BAD[case]
    argv = list(argv)
    if "--effect" not in argv:
        argv += ["--effect", "pickup_line"]
    defaults = {"--grid": "amplitude_V=0.001:0.002:2", "--seeds": "2", "--duration": DURATION}
    for opt, v in defaults.items():
        if opt not in argv:
            argv += [opt, v]
    if case == "out-file":
        out.write_text("x\n")
    elif case == "out-missing-parent":
        out = tmp_path / "no" / "camp"
    elif case.startswith("out-"):
        out.mkdir()
        row = {
            "out-not-runs": None,
            "out-other-effect": OTHER_RUN,
            "out-other-record": NULL_300,
            "out-other-fixed": OTHER_RUN
            | {
                "effect": "pickup_line",
                "grid": "amplitude_V",
                "params": {"freq_hz": 200.0, "amplitude_V": 0.001},
            },
        }[case]
        (out / "runs.jsonl").write_text("not json\n" if row is None else json.dumps(row) + "\n")
    before = sorted((p.name, p.read_bytes()) for p in out.iterdir()) if out.is_dir() else None
    err = _refused(capsys, [*argv, "--out", str(out)])
    assert err.startswith("fbs campaign: error: ") and named in err, err
    assert (
        sorted((p.name, p.read_bytes()) for p in out.iterdir()) if out.is_dir() else None
    ) == before
    assert not (tmp_path / "no").exists() and (case.startswith("out-") or not out.exists())


def _args(*argv: str) -> argparse.Namespace:
    return build_parser().parse_args(["campaign", *argv])


def test_force_takes_a_dir_of_another_campaign_afresh(tmp_path):
    out = tmp_path / "camp"
    out.mkdir()
    (out / "runs.jsonl").write_text(json.dumps(OTHER_RUN) + "\n" + '{"torn')
    argv = [*EFFECT, "--grid", "amplitude_V=0.001:0.002:2", "--seeds", "2", "--out", str(out)]
    with pytest.raises(CampaignError, match="another campaign"):
        plan_of(_args(*argv))
    c = plan_of(_args(*argv, "--force"))
    assert c.replace and c.latest == {} and c.torn_tail == 0 and len(c.todo()) == 6


def test_the_campaign_plan_resumes_runs_of_the_same_campaign_with_another_grid(tmp_path):
    """Grid and seeds may change within a campaign: the runs already there are reused by key."""
    out = tmp_path / "camp"
    out.mkdir()
    row = OTHER_RUN | {
        "effect": "pickup_line",
        "grid": "amplitude_V",
        "params": {"freq_hz": 200.0, "amplitude_V": 0.002},
    }
    (out / "runs.jsonl").write_text(json.dumps(row) + "\n" + json.dumps(row | {"seed": 7}) + "\n")
    c = plan_of(
        _args(*EFFECT, "--grid", "amplitude_V=0.001:0.003:3", "--seeds", "3", "--out", str(out))
    )
    assert c.grid.values == [0.001, 0.002, 0.003]
    assert len(c.runs()) == 12 and len(c.todo()) == 11  # seed 1 at 0.002 is done; seed 7 unused
    assert c.runs()[0][1] == ("none", None, {}, 1, 74.0)


# ---------------------------------------------------------------------------- units: the grid
PICKUP = effects.get("pickup_line")


@settings(max_examples=300, deadline=None)
@given(lo=st.floats(1e-4, 0.1), hi=st.floats(1e-4, 0.1), n=st.integers(1, 60), log=st.booleans())
def test_a_grid_is_n_distinct_values_from_lo_to_hi_or_refused(lo, hi, n, log):
    text = f"amplitude_V={lo!r}:{hi!r}:{n}"
    try:
        g = parse_grid(text, PICKUP, log)
    except CampaignError as exc:
        assert str(exc).startswith(f"--grid {text!r}: ")
        assert (n == 1 and lo != hi) or (n > 1 and lo >= hi) or "not distinct" in str(exc)
        return
    v = g.values
    assert len(v) == n and v[0] == lo and v[-1] == hi
    assert all(a < b for a, b in zip(v, v[1:]))  # strictly increasing: distinct
    assert all(PICKUP.params[1].lo <= x <= PICKUP.params[1].hi for x in v)
    assert v == parse_grid(text, PICKUP, log).values  # the same text, the same values
    if n > 2:
        steps = np.diff(np.log(v) if log else np.array(v))
        assert np.allclose(steps, steps[0], rtol=1e-6, atol=1e-12 * max(abs(hi), 1))


@given(text=st.text(max_size=40))
@settings(max_examples=300, deadline=None)
def test_any_grid_text_is_parsed_or_refused_with_a_campaign_error(text):
    try:
        g = parse_grid(text, PICKUP)
    except CampaignError:
        return
    assert g.param in ("freq_hz", "amplitude_V") and 1 <= g.n <= campaign_plan.MAX_GRID_POINTS
    assert all(math.isfinite(x) for x in g.values)


def test_grid_values_are_even_or_geometric_and_rounded():
    assert parse_grid("amplitude_V=0.001:0.003:3", PICKUP).values == [0.001, 0.002, 0.003]
    assert parse_grid("amplitude_V=0.0001:0.01:3", PICKUP, log=True).values == [0.0001, 0.001, 0.01]
    assert parse_grid("freq_hz=100:100:1", PICKUP).values == [100.0]
    assert parse_grid(" freq_hz = 10 : 30 : 3 ", PICKUP).values == [10.0, 20.0, 30.0]
    assert parse_grid("amplitude_V=0.1:0.1:1", PICKUP).text == "amplitude_V=0.1:0.1:1"
    assert parse_grid("freq_hz=50.0:2e2:4", PICKUP).text == "freq_hz=50:200:4"


# ---------------------------------------------------------------------------- units: the curves
def _row(
    effect: str,
    params: dict,
    seed: int,
    named: list[str],
    fitted: dict | None = None,
    *,
    significant: bool | None = None,
    error: str | None = None,
) -> dict:
    return {
        "effect": effect,
        "grid": "amplitude_V" if effect != "none" else None,
        "params": params,
        "seed": seed,
        "record": campaign_task.record_spec(74.0),
        "exit": 0 if error is None else 2,
        "named": named,
        "significant": bool(named) if significant is None else significant,
        "explained": True,
        "fitted": fitted or {},
        "fitted_ci95": {},
        "gap_before_db": 1.0,
        "gap_after_db": 0.0,
        "warnings": [],
        "error": error,
        "elapsed_s": 1.0,
    }


def test_curves_table_and_plot_of_synthetic_runs(tmp_path):
    c = plan_of(
        _args(
            *EFFECT,
            "--grid",
            "amplitude_V=0.001:0.002:2",
            "--log",
            "--seeds",
            "2",
            "--set",
            "freq_hz=150",
            "--out",
            str(tmp_path / "camp"),
        )
    )
    for s in (1, 2):
        for r in (
            _row("none", {}, s, []),
            _row(
                "pickup_line",
                c.params_at(0.002),
                s,
                ["pickup_line"],
                {"amplitude_V": 0.0021, "freq_hz": 150.0},
            ),
        ):
            c.latest[key(r)] = r
    (tmp_path / "camp").mkdir()
    cv = campaign.compute_curves(c)
    campaign.write_curves(c, cv)
    md = (tmp_path / "camp" / "curves.md").read_text()
    assert "other parameters: freq_hz = 150" in md and "--set freq_hz=150 " in md and "--log" in md
    assert "| 0.001 | 0 | 0 | - | - | - | - |" in md  # not run yet
    assert (
        "| 0.002 | 2 | 2 | 1.00 | 0.34-1.00 | +5.0 % [+5.0 %, +5.0 %] | +0.0 % [+0.0 %, +0.0 %] |"
        in md
    )
    assert "0 of 2 (0.00, 95 % 0.00-0.66" in md
    assert "incomplete: 4 of 6 runs have a result" in md
    assert json.loads((tmp_path / "camp" / "curves.json").read_text()) == json.loads(json.dumps(cv))
    assert (tmp_path / "camp" / "curves.png").read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in (tmp_path / "camp").iterdir()) == [
        "curves.json",
        "curves.md",
        "curves.png",
    ]


# ---------------------------------------------------------------------------- units: the record
def test_the_campaign_record_is_the_detection_limit_suites(tmp_path):
    """``campaign_task.simulate_record`` writes what the hidden-effect suite's ``make_hidden`` does."""
    spec = importlib.util.spec_from_file_location(
        "fbs_tests_gap_conftest_for_campaign", GAP_TESTS / "conftest.py"
    )
    suite = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(suite)
    kinds = {"ac_x_ctl": "ctl", "ac_x_inst": "inst", "gyro_x": "gyro", "pa_x": "pa"}
    assert campaign_task.RANGES_V == {c: suite.HIDDEN_RANGES_V[k] for c, k in kinds.items()}
    import h5py

    params = {"freq_hz": 120.0, "amplitude_V": 0.004}
    a = campaign_task.simulate_record(tmp_path / "a.h5", "pickup_line", params, 7, duration_s=5.0)
    b = suite.make_hidden(
        tmp_path / "b.h5",
        ["pickup_line:" + ",".join(f"{k}={v!r}" for k, v in params.items())],
        seed=7,
        duration_s=5.0,
    )
    with h5py.File(a) as fa, h5py.File(b) as fb:
        assert sorted(fa["channels"]) == sorted(fb["channels"]) == sorted(campaign_task.RANGES_V)
        for c in fa["channels"]:
            assert np.array_equal(fa["channels"][c][()], fb["channels"][c][()])
            assert fa["channels"][c][()].size == 5000
        for k in ("mode", "axis", "format"):
            assert fa.attrs[k] == fb.attrs[k]
