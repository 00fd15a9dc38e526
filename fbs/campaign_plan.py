"""What ``fbs campaign gap`` will run, every argument checked before any work starts.

The grid (``--grid PARAM=LO:HI:N``, ``--log``), the effect's other parameters (``--set``), the
seeds, the record's duration and DIR are parsed and checked against the effect's catalogue entry
(``CampaignError`` names the bad value; exit 2). ``plan_of`` gives the ``Campaign``: its runs (the
null run and every grid value, seed by seed) and which of them DIR's ``runs.jsonl`` already holds,
so that a campaign run again goes on where it stopped (resume); a DIR holding another campaign's
runs is refused unless ``--force``. Executing the plan is ``fbs.campaign``'s.
"""

from __future__ import annotations

import argparse
import math
import os
import shlex
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fbs import batch_exec, campaign_task
from procedures.analysis.gap.detection import run_key

#: a grid's values are rounded to this many significant digits (they key the runs in runs.jsonl)
GRID_DIGITS = 12
MAX_GRID_POINTS = 1000
MAX_SEEDS = 10_000
MAX_DURATION_S = 3600.0
#: DIR's runs, one line each (``fbs.campaign_task.RUN_KEYS``)
RUNS_FILE = "runs.jsonl"
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
