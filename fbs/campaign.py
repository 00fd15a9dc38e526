"""``fbs campaign gap --effect NAME --grid PARAM=LO:HI:N --seeds N [--set K=V ...] [--log]
[--duration S] [--jobs N] [--scheduler ADDR] [--force] [--json] --out DIR``
(DESIGN.md section 7; docs/batch.md section 5; issue 23 part 2).

Detection curves of the model-gap workflow: for every value of the effect's parameter PARAM on
the grid (N points from LO to HI, evenly spaced, or geometrically with ``--log``; the effect's
other parameters at their catalogue defaults or as ``--set``) and every seed 1..N, the
detection-limit record of docs/gap.md section 6 is simulated with the effect injected
(``fbs.campaign_task``), and the gap workflow run on it; so are null runs (no effect, the same
seeds). The runs go through ``fbs batch``'s executors (``fbs.batch_exec``: a local process pool
with one BLAS thread per worker, or a Dask cluster with ``--scheduler``).

Output in DIR:

- ``runs.jsonl``: one line per run (``fbs.campaign_task.RUN_KEYS``), appended and synced as each
  finishes. Resumable: runs already there (same effect, parameter values, seed and record) are
  skipped; runs whose newest line is an error are run again. A DIR holding runs of another
  campaign (another effect, grid parameter, fixed parameter value or record) is refused unless
  ``--force``, which moves its runs to ``runs.jsonl.old`` and starts afresh. The grid and the
  number of seeds may change between runs of one campaign (points and seeds already run are
  reused).
- ``curves.json`` (also what ``--json`` prints), ``curves.md`` (a table docs can quote),
  ``curves.png``: per grid value the probability that the workflow names the injected effect
  first, with its 95 % Wilson interval; the parameter errors (fitted / true - 1: median and the
  16th and 84th percentiles, over the runs named right); and over the null runs the false-alarm
  rate (a null run that is significant, or has an effect named), with its interval.

This module is the command and the execution, which runs on ``fbs batch``'s machinery
(``fbs.batch_exec``), so it lives in the command-line layer with the plan it executes
(``fbs.campaign_plan``: the arguments checked, the runs, what DIR already holds). The curves'
statistics are ``procedures.analysis.gap.detection``'s; their table and plot are
``procedures.reports.detection_curves``'s.

Every argument is checked before any work starts (exit 2, ``fbs campaign: error: ...``).
Exit 0: every run has a result; 2: some run's newest line is an error (run again to retry it),
or interrupted (SIGINT, SIGTERM, SIGHUP: finished runs stay, the curves of what is done are
written), or refused.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

from fbs import batch_exec, campaign_task, jsonout
from fbs.campaign_plan import RUNS_FILE, WORKFLOWS, Campaign, plan_of
from procedures.analysis.gap.detection import curves
from procedures.held_signals import signals_held
from procedures.reports.detection_curves import curves_markdown, plot_curves

CURVES_JSON, CURVES_MD, CURVES_PNG = "curves.json", "curves.md", "curves.png"


def compute_curves(c: Campaign) -> dict[str, Any]:
    """The detection curves of the runs of ``c`` done so far (its newest line per run)."""
    return curves(
        c.effect,
        c.grid,
        c.params_at,
        c.seeds,
        c.latest,
        meta={
            "effect": c.effect,
            "grid": {
                "param": c.grid.param,
                "lo": c.grid.lo,
                "hi": c.grid.hi,
                "n": c.grid.n,
                "log": c.grid.log,
            },
            "fixed": c.fixed,
            "seeds": c.n_seeds,
            "record": c.record,
            "channels_V": campaign_task.RANGES_V,
            "command": c.command(),
        },
    )


def _write_atomically(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def write_curves(c: Campaign, cv: dict[str, Any]) -> None:
    _write_atomically(c.out / CURVES_JSON, jsonout.dumps(cv, indent=1) + "\n")
    _write_atomically(c.out / CURVES_MD, curves_markdown(cv))
    tmp = plot_curves(cv, c.out / f".{CURVES_PNG}.tmp.png")
    os.replace(tmp, c.out / CURVES_PNG)


# ---------------------------------------------------------------------------- the run
def _say(text: str) -> None:
    print(f"fbs campaign: {text}", file=sys.stderr, flush=True)


def _run_name(rec: dict[str, Any]) -> str:
    if rec["effect"] == "none":
        return f"null run, seed {rec['seed']}"
    return f"{rec['effect']} {rec['grid']}={rec['params'][rec['grid']]:g}, seed {rec['seed']}"


def _lost(args: tuple[Any, ...], exc: BaseException) -> dict[str, Any]:
    effect, grid, params, seed, duration_s = args
    line: dict[str, Any] = dict.fromkeys(campaign_task.RUN_KEYS)
    line |= {
        "effect": effect,
        "grid": grid,
        "params": params,
        "seed": seed,
        "record": campaign_task.record_spec(duration_s),
        "exit": 2,
        "named": [],
        "fitted": {},
        "fitted_ci95": {},
        "warnings": [],
        "error": f"{batch_exec.lost_reason(exc)}; run the campaign again to retry it",
        "elapsed_s": 0.0,
    }
    return line


def _execute(c: Campaign, backend: batch_exec.Backend, results: batch_exec.ResultsFile) -> None:
    todo = c.todo()
    args_of = dict(todo)
    n_todo, n_done, n_err = len(todo), 0, 0
    t0 = time.monotonic()

    def done(key: tuple[Any, ...], rec: Any, exc: BaseException | None) -> None:
        nonlocal n_done, n_err
        if exc is not None:
            rec = _lost(args_of[key], exc)
        with signals_held():  # the line and the curves' view of it together
            results.append(rec)
            c.latest[key] = rec
        n_done += 1
        n_err += rec["error"] is not None
        if rec["error"] is not None:
            how = f"exit {rec['exit']}: {rec['error'].splitlines()[-1]}"
        else:
            how = (
                "named " + ", ".join(rec["named"])
                if rec["named"]
                else "significant, nothing named"
                if rec["significant"]
                else "nothing named"
            )
        _say(
            f"[{n_done}/{n_todo}] {_run_name(rec)}: {how} ({rec['elapsed_s']:.1f} s); {n_err} error(s), "
            f"{time.monotonic() - t0:.0f} s elapsed"
        )

    def interrupted(n_done: int, n_in_flight: int, n_not_submitted: int) -> None:
        _say(
            f"interrupted: {n_done} run(s) of this invocation kept in {c.runs_path}, {n_in_flight} unfinished "
            f"cancelled, {n_not_submitted} not submitted; run the same command again to go on"
        )
        write_curves(c, compute_curves(c))
        _say(f"curves of the runs done so far in {c.out}/{CURVES_MD}, .json, .png")

    def retrying(key: tuple[Any, ...], exc: BaseException) -> None:
        effect, grid, params, seed, _ = args_of[key]
        _say(
            f"{_run_name({'effect': effect, 'grid': grid, 'params': params, 'seed': seed})}: "
            f"{batch_exec.lost_reason(exc)}; submitted again"
        )

    # a local worker killed under its run (which takes the other runs in flight in its pool down
    # with it) costs those runs one more try here, not an error line
    batch_exec.run_tasks(
        backend, campaign_task.run, todo, done, interrupted, retry_lost=1, retrying=retrying
    )


def _campaign(args: argparse.Namespace) -> int:
    c = plan_of(args)
    todo = c.todo()
    runs = c.runs()
    retried = sum(1 for k, _ in todo if k in c.latest)
    backend = (
        batch_exec.open_backend(batch_exec.local_jobs(c.jobs, c.scheduler, len(todo)), c.scheduler)
        if todo
        else None
    )
    try:
        c.out.mkdir(exist_ok=True)
        if c.replace:
            os.replace(c.runs_path, c.out / f"{RUNS_FILE}.old")
            _say(f"--force: the runs of another campaign in {c.out} moved to {RUNS_FILE}.old")
        results = batch_exec.ResultsFile(c.runs_path)
        results.cut(c.torn_tail)
    except BaseException:
        if backend:
            backend.close()
        raise
    try:
        if c.torn_tail:
            _say(
                f"dropped an unfinished last line ({c.torn_tail} bytes) a killed campaign left in {c.runs_path}"
            )
        _say(
            f"{c.describe()}: {len(runs)} run(s) ({c.grid.n} value(s) x {c.n_seeds} seed(s) + {c.n_seeds} null), "
            f"{len(runs) - len(todo)} already done in {c.runs_path} (skipped)"
            + (f", {retried} earlier error(s) retried" if retried else "")
            + (f"; {len(todo)} to run on {backend.describe()}" if backend else "; nothing to run")
        )
        if backend:
            try:
                _execute(c, backend, results)
            finally:
                backend.close()
    finally:
        results.close()
    cv = compute_curves(c)
    write_curves(c, cv)
    code = 0 if cv["complete"] else 2
    _say(
        f"{cv['runs']} run(s), {cv['errors']} with an error; curves in {c.out}/{CURVES_MD} (.json, .png); exit {code}"
    )
    if args.json:
        print(jsonout.dumps(cv))
    return code


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "campaign",
        help="Monte-Carlo detection curves of the model-gap workflow over an effect's "
        "parameter grid and seeds (local processes or a Dask cluster)",
        description="Simulates the detection-limit record (mode 3, axis X: ac_x_ctl, ac_x_inst, gyro_x, "
        "pa_x at 1 kHz) with the effect "
        "injected at every grid value and seed, and without it (null runs), runs the gap workflow on "
        "each, and writes DIR/runs.jsonl (one line per run, resumable), DIR/curves.json, curves.md and "
        "curves.png: P(effect named) with 95 % Wilson intervals, parameter errors, false-alarm rate. "
        "Exit 0 every run done, 2 some run failed (run again to retry), interrupted or refused.",
    )
    p.add_argument("workflow", metavar="WORKFLOW", help=f"what to run: {', '.join(WORKFLOWS)}")
    p.add_argument(
        "--effect",
        required=True,
        metavar="NAME",
        help="the effect to inject (e.g. pickup_line, "
        "bearing_friction; an unknown name is refused with the catalogue listed)",
    )
    p.add_argument(
        "--grid",
        required=True,
        metavar="PARAM=LO:HI:N",
        help="the effect's parameter and its N values from LO to HI, e.g. amplitude_V=0.0001:0.01:5",
    )
    p.add_argument("--log", action="store_true", help="space the grid geometrically (LO > 0)")
    p.add_argument(
        "--set",
        action="append",
        metavar="PARAM=VALUE",
        help="another parameter of the effect (default: the catalogue's), e.g. --set freq_hz=50; repeat "
        "or separate with commas",
    )
    p.add_argument(
        "--seeds",
        required=True,
        metavar="N",
        help="seeds 1..N at every grid value, and N null runs",
    )
    p.add_argument(
        "--duration",
        metavar="S",
        help=f"record length, s (default {campaign_task.DURATION_S:g}, the "
        "detection-limit record's; at least what the gap workflow needs, 73.728 s)",
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="runs.jsonl and the curves; an existing one of the same campaign is resumed",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help=f"start afresh in a DIR holding another campaign's runs (moved to {RUNS_FILE}.old)",
    )
    p.add_argument(
        "--jobs",
        metavar="N",
        help="local processes (default: one per core); with --scheduler, the "
        "most runs in flight at once (default: all)",
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDR",
        help="a Dask distributed scheduler, e.g. tcp://host:8786 "
        f"(needs {batch_exec.CLUSTER_EXTRA})",
    )
    p.add_argument(
        "--json", action="store_true", help="print the curves as one JSON object on stdout"
    )
    p.set_defaults(func=_campaign)
