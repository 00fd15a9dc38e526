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

This module is the command: its arguments, the plan and the resumable execution (which run on
``fbs batch``'s machinery, so they live in the command-line layer). The curves' statistics are
``procedures.analysis.gap.detection``'s, their table and plot ``procedures.reports.detection_curves``'s.

Every argument is checked before any work starts (exit 2, ``fbs campaign: error: ...``).
Exit 0: every run has a result; 2: some run's newest line is an error (run again to retry it),
or interrupted (SIGINT, SIGTERM, SIGHUP: finished runs stay, the curves of what is done are
written), or refused.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import sys
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fbs import batch_exec, campaign_task
from procedures.analysis.gap.detection import curves, run_key
from procedures.reports.detection_curves import curves_markdown, plot_curves

#: a grid's values are rounded to this many significant digits (they key the runs in runs.jsonl)
GRID_DIGITS = 12
MAX_GRID_POINTS = 1000
MAX_SEEDS = 10_000
MAX_DURATION_S = 3600.0
RUNS_FILE, CURVES_JSON, CURVES_MD, CURVES_PNG = (
    "runs.jsonl",
    "curves.json",
    "curves.md",
    "curves.png",
)
#: the workflows a campaign runs (``fbs campaign WORKFLOW``)
WORKFLOWS = ("gap",)


class CampaignError(ValueError):
    """A bad argument or DIR, refused before any work starts (exit 2)."""


# ---------------------------------------------------------------------------- the grid
@dataclass(frozen=True)
class Grid:
    """``PARAM=LO:HI:N``: N values from LO to HI, evenly or (``log``) geometrically spaced."""

    param: str
    lo: float
    hi: float
    n: int
    log: bool = False

    @property
    def values(self) -> list[float]:
        return grid_values(self.lo, self.hi, self.n, self.log)

    @property
    def text(self) -> str:
        return f"{self.param}={_exact(self.lo)}:{_exact(self.hi)}:{self.n}"


def _exact(x: float) -> str:
    """``x`` as text that reads back as ``x`` (``50``, not ``50.0``)."""
    r = repr(float(x))
    return r[:-2] if r.endswith(".0") else r


def _rounded(x: float) -> float:
    return float(f"{x:.{GRID_DIGITS}g}")


def grid_values(lo: float, hi: float, n: int, log: bool = False) -> list[float]:
    """N values from LO to HI (both exact; between, rounded to ``GRID_DIGITS`` digits)."""
    if n == 1:
        return [lo]
    if log:
        a, b = math.log(lo), math.log(hi)
        inner = [math.exp(a + (b - a) * i / (n - 1)) for i in range(1, n - 1)]
    else:
        inner = [lo + (hi - lo) * i / (n - 1) for i in range(1, n - 1)]
    return [lo, *(_rounded(v) for v in inner), hi]


def _number(text: str, what: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise CampaignError(f"{what} {text!r} is not a number") from None
    if not math.isfinite(x):
        raise CampaignError(f"{what} {text!r} is not a finite number")
    return x


def _whole(text: str, what: str, lo: int, hi: int) -> int:
    try:
        x = int(text)
    except ValueError:
        raise CampaignError(f"{what} {text!r} is not a whole number") from None
    if not lo <= x <= hi:
        raise CampaignError(f"{what} {text!r} must be {lo} to {hi}")
    return x


def _param_names(effect: Any) -> str:
    return ", ".join(f"{p.name} ({p.lo:g}..{p.hi:g}, default {p.default:g})" for p in effect.params)


def _in_prior(effect: Any, name: str, x: float, what: str) -> None:
    p = next(q for q in effect.params if q.name == name)
    if not p.lo <= x <= p.hi:
        raise CampaignError(
            f"{what}: {name} = {x:g} is outside the effect's range {p.lo:g}..{p.hi:g}"
        )


def parse_grid(text: str, effect: Any, log: bool = False) -> Grid:
    """``PARAM=LO:HI:N`` for ``effect`` (a ``simhw.effects.Effect``), checked: PARAM one of its
    parameters, LO and HI finite numbers within its range, LO < HI (LO = HI for N = 1), N a whole
    number 1..``MAX_GRID_POINTS``, N distinct values (and LO > 0 for ``log``)."""
    what = f"--grid {text!r}"
    name, eq, rest = text.partition("=")
    parts = rest.split(":")
    if not eq or len(parts) != 3:
        raise CampaignError(
            f"{what}: expected PARAM=LO:HI:N, e.g. {effect.params[0].name}="
            f"{effect.params[0].lo:g}:{effect.params[0].hi:g}:5"
        )
    name = name.strip()
    if name not in {p.name for p in effect.params}:
        raise CampaignError(
            f"{what}: {effect.name} has no parameter {name!r}; its parameters: "
            f"{_param_names(effect)}"
        )
    lo, hi = _number(parts[0].strip(), f"{what}: LO"), _number(parts[1].strip(), f"{what}: HI")
    n = _whole(parts[2].strip(), f"{what}: N", 1, MAX_GRID_POINTS)
    if n == 1 and lo != hi:
        raise CampaignError(
            f"{what}: N = 1 is one value; give it as LO and HI both ({name}={lo!r}:{lo!r}:1)"
        )
    if n > 1 and not lo < hi:
        raise CampaignError(f"{what}: LO must be below HI for N > 1")
    if log and lo <= 0:
        raise CampaignError(f"{what}: --log spaces the values geometrically: LO must be above 0")
    for x in (lo, hi):
        _in_prior(effect, name, x, what)
    grid = Grid(name, lo, hi, n, log)
    values = grid.values
    if any(a >= b for a, b in zip(values, values[1:])):
        raise CampaignError(
            f"{what}: {n} values between {lo!r} and {hi!r} are not distinct to {GRID_DIGITS} "
            f"digits; give fewer"
        )
    return grid


def parse_sets(items: Iterable[str], effect: Any, grid_param: str) -> dict[str, float]:
    """``--set K=V`` (repeated, or ``K=V,K=V``): the effect's other parameters, checked."""
    out: dict[str, float] = {}
    for item in (s.strip() for text in items for s in text.split(",")):
        if not item:
            continue
        k, eq, v = item.partition("=")
        k = k.strip()
        what = f"--set {item!r}"
        if not eq:
            raise CampaignError(f"{what}: expected PARAM=VALUE")
        if k not in {p.name for p in effect.params}:
            raise CampaignError(
                f"{what}: {effect.name} has no parameter {k!r}; its parameters: {_param_names(effect)}"
            )
        if k == grid_param:
            raise CampaignError(f"{what}: {k} is the --grid parameter")
        if k in out:
            raise CampaignError(f"{what}: {k} is set twice")
        out[k] = _number(v.strip(), what)
        _in_prior(effect, k, out[k], what)
    return out


# ---------------------------------------------------------------------------- the plan
@dataclass
class Campaign:
    """What ``fbs campaign gap`` will do, every argument checked."""

    effect: str
    grid: Grid
    fixed: dict[str, float]  # every other parameter of the effect, as injected
    n_seeds: int
    duration_s: float
    out: Path
    jobs: int | None = None
    scheduler: str | None = None
    param_order: tuple[str, ...] = ()
    latest: dict[tuple[Any, ...], dict[str, Any]] = field(
        default_factory=dict
    )  # runs.jsonl's newest line per run
    torn_tail: int = 0
    replace: bool = False  # --force over another campaign's runs

    @property
    def seeds(self) -> list[int]:
        return list(range(1, self.n_seeds + 1))

    @property
    def record(self) -> dict[str, Any]:
        return campaign_task.record_spec(self.duration_s)

    @property
    def runs_path(self) -> Path:
        return self.out / RUNS_FILE

    def params_at(self, value: float) -> dict[str, float]:
        full = self.fixed | {self.grid.param: value}
        return {k: full[k] for k in self.param_order}

    def runs(self) -> list[tuple[tuple[Any, ...], tuple[Any, ...]]]:
        """``(key, args of campaign_task.run)`` of every run, seed by seed: the null run, then the grid."""
        out: list[tuple[tuple[Any, ...], tuple[Any, ...]]] = []
        for s in self.seeds:
            out.append((run_key("none", {}, s), ("none", None, {}, s, self.duration_s)))
            for v in self.grid.values:
                p = self.params_at(v)
                out.append(
                    (
                        run_key(self.effect, p, s),
                        (self.effect, self.grid.param, p, s, self.duration_s),
                    )
                )
        return out

    def todo(self) -> list[tuple[tuple[Any, ...], tuple[Any, ...]]]:
        return [
            r
            for r in self.runs()
            if self.latest.get(r[0], {"error": "missing"})["error"] is not None
        ]

    def command(self) -> str:
        """The command line of this campaign (for curves.md)."""
        words = ["fbs", "campaign", "gap", "--effect", self.effect, "--grid", self.grid.text]
        words += ["--log"] if self.grid.log else []
        words += ["--seeds", str(self.n_seeds)]
        defaults = _defaults(self.effect)
        for k, v in self.fixed.items():
            if v != defaults[k]:
                words += ["--set", f"{k}={_exact(v)}"]
        if self.duration_s != campaign_task.DURATION_S:
            words += ["--duration", f"{self.duration_s:g}"]
        return shlex.join([*words, "--out", str(self.out)])

    def describe(self) -> str:
        fixed = ", ".join(f"{k} = {v:g}" for k, v in self.fixed.items())
        return (
            f"{self.effect} over {self.grid.param}"
            + (f" ({fixed})" if fixed else "")
            + f", {self.duration_s:g} s records"
        )


def _defaults(effect: str) -> dict[str, float]:
    from simhw import effects

    return {p.name: p.default for p in effects.get(effect).params}


def _min_duration_s() -> float:
    """The shortest record the gap workflow analyses at the campaign's rate."""
    from procedures.analysis.gap.grid import MIN_SEGMENTS, make_grid

    probe = make_grid(campaign_task.RATE_HZ, 1 << 30)
    need = probe.nperseg + (MIN_SEGMENTS - 1) * (probe.nperseg - probe.noverlap)
    return need / campaign_task.RATE_HZ


def _duration(text: str | None) -> float:
    if text is None:
        return campaign_task.DURATION_S
    d = _number(text, "--duration")
    lo = _min_duration_s()
    if not lo <= d <= MAX_DURATION_S:
        raise CampaignError(
            f"--duration {text!r} must be {lo:g} to {MAX_DURATION_S:g} s (the gap workflow needs "
            f"{lo:g} s at {campaign_task.RATE_HZ:g} Hz)"
        )
    return d


def _out_dir(text: str) -> Path:
    out = Path(text)
    if out.exists() or out.is_symlink():
        if not out.is_dir():
            raise CampaignError(f"--out {out} is not a directory")
        if not os.access(out, os.R_OK | os.W_OK | os.X_OK):
            raise CampaignError(f"--out {out} cannot be read and written (permissions)")
        runs = out / RUNS_FILE
        if (runs.exists() or runs.is_symlink()) and not runs.is_file():
            raise CampaignError(f"--out {out}: {runs} is not a regular file")
    else:
        parent = out.absolute().parent
        if not parent.is_dir():
            raise CampaignError(f"--out {out}: the directory {parent} does not exist")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise CampaignError(f"--out {out}: the directory {parent} is not writable")
    return out


def _describe_run(rec: dict[str, Any]) -> str:
    rd = rec.get("record") or {}
    what = (
        "a null run"
        if rec.get("effect") == "none"
        else (
            f"{rec.get('effect')} over {rec.get('grid')} at "
            + ", ".join(f"{k} = {v!r}" for k, v in (rec.get("params") or {}).items())
        )
    )
    return f"{what}, {rd.get('duration_s')} s at {rd.get('rate_hz')} Hz, mode {rd.get('mode')}, axis {rd.get('axis')}"


def _foreign(c: Campaign, rec: dict[str, Any]) -> bool:
    """A line of runs.jsonl that is not a run of this campaign."""
    if rec.get("record") != c.record:
        return True
    if rec.get("effect") == "none":
        return rec.get("params") != {}
    if rec.get("effect") != c.effect or rec.get("grid") != c.grid.param:
        return True
    params = rec.get("params")
    return (
        not isinstance(params, dict)
        or set(params) != set(c.param_order)
        or any(params[k] != v for k, v in c.fixed.items())
    )


def _read_runs(c: Campaign, force: bool) -> None:
    """Check DIR's runs.jsonl holds runs of this campaign and note its newest line per run."""
    path = c.runs_path
    if not path.exists():
        return
    try:
        lines, c.torn_tail = batch_exec.read_results(path)
    except ValueError as exc:
        if force:
            c.replace = True
            return
        raise CampaignError(
            f"--out {c.out}: {path} is not a campaign's runs file ({exc}); give another --out, "
            f"or --force to start afresh"
        ) from None
    for n, rec in lines:
        missing = [k for k in campaign_task.RUN_KEYS if not (isinstance(rec, dict) and k in rec)]
        if missing or _foreign(c, rec):
            if force:
                c.replace, c.latest, c.torn_tail = True, {}, 0
                return
            if missing:
                raise CampaignError(
                    f"--out {c.out}: {path} is not a campaign's runs file (line {n} has no "
                    f"{', '.join(missing)}); give another --out, or --force to start afresh"
                )
            raise CampaignError(
                f"--out {c.out} holds runs of another campaign (line {n}: {_describe_run(rec)}); "
                f"this one is {c.describe()}: give another --out, or --force to start afresh "
                f"(the runs there are moved to {RUNS_FILE}.old)"
            )
        c.latest[run_key(rec["effect"], rec["params"], rec["seed"])] = rec


def plan_of(args: argparse.Namespace) -> Campaign:
    """Every argument checked (``CampaignError`` naming the bad value); nothing written."""
    from simhw import effects

    if args.workflow not in WORKFLOWS:
        raise CampaignError(
            f"unknown workflow {args.workflow!r}; fbs campaign runs {', '.join(WORKFLOWS)}"
        )
    catalogue = effects.catalogue()
    if args.effect not in catalogue:
        raise CampaignError(
            f"unknown effect {args.effect!r}; the catalogue: "
            f"{', '.join(n for n in catalogue if n != 'none')}"
        )
    if args.effect == "none":
        raise CampaignError(
            "--effect none has nothing to detect: every campaign runs the null runs; name an effect "
            f"of the catalogue: {', '.join(n for n in catalogue if n != 'none')}"
        )
    effect = catalogue[args.effect]
    grid = parse_grid(args.grid, effect, args.log)
    sets = parse_sets(args.set or [], effect, grid.param)
    fixed = {p.name: sets.get(p.name, p.default) for p in effect.params if p.name != grid.param}
    n_seeds = _whole(args.seeds, "--seeds", 1, MAX_SEEDS)
    duration = _duration(args.duration)
    jobs = batch_exec.parse_jobs(args.jobs)
    out = _out_dir(args.out)
    c = Campaign(
        effect.name,
        grid,
        fixed,
        n_seeds,
        duration,
        out,
        jobs,
        args.scheduler,
        tuple(p.name for p in effect.params),
    )
    _read_runs(c, args.force)
    return c


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
    _write_atomically(c.out / CURVES_JSON, json.dumps(cv, indent=1) + "\n")
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
        with batch_exec.signals_held():  # the line and the curves' view of it together
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
        print(json.dumps(cv))
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
