"""``fbs batch COMMAND FILES... [--jobs N] [--scheduler ADDR] [--args 'OPTIONS'] --out RESULTS.jsonl``
(DESIGN.md section 7; docs/batch.md).

Runs one analysis command on many run files in parallel - ``gap``, ``inspect``, ``spectra``,
``analyze-hysteresis``, ``analyze-transfer`` (``fbs.batch_task.COMMANDS``) - each file exactly as
``fbs COMMAND FILE --json OPTIONS`` would (the same parser, the same function behind ``--json``),
in a local process pool (default; ``--jobs`` processes, default one per core) or on a Dask
distributed cluster (``--scheduler ADDR``; the optional extra ``fbs-hil[cluster]``).

Output: one JSON line per file, appended to ``--out`` (and synced) as each finishes:
``{"file", "command", "args", "exit", "result", "error", "elapsed_s"}`` - the absolute path, the
COMMAND, the ``--args`` words, the single command's exit code (0; 2 for a file it refuses, with
its message in ``error``; 1 with a traceback for a crash), its ``--json`` object (null on error),
and the seconds it took. A progress line per file goes to stderr.

Resuming: run the same command again. Files that already have a result in ``--out`` are skipped
(counted on stderr); files whose last line is an error are run again (the newest line of a file
is its result). An ``--out`` written for another COMMAND or other ``--args`` is refused.

Every argument is checked before any work starts, and refused with exit 2 naming the bad value:
an unknown COMMAND, no FILE, a FILE that is not a regular file, ``--jobs`` not a whole number
>= 1, ``--args`` the command does not take (or one that would send every file's output to one
place), an ``--out`` that cannot be written or that is not a batch results file, no
``distributed`` or no scheduler at ``--scheduler``.

SIGINT, SIGTERM or SIGHUP (``fbs.signals``): nothing more is submitted, what has not started is
cancelled, the workers are ended and every finished result stays in ``--out``; exit 2.

Exit code: 0 every file's command exited 0; 1 some exited 1 and none failed; 2 some file has an
error (its newest line), or the batch was interrupted or refused.
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fbs import batch_exec, batch_task


class BatchError(ValueError):
    """A bad argument or ``--out``, refused before any work starts (exit 2)."""


@dataclass
class Plan:
    """What ``fbs batch`` will do, every argument checked."""

    command: str
    extra: list[str]
    files: list[str]  # absolute paths, in the order given, each once
    out: Path
    jobs: int | None
    scheduler: str | None
    latest: dict[str, dict[str, Any]] = field(default_factory=dict)  # --out's newest line per file
    torn_tail: int = 0  # bytes of an unfinished last line in --out (a killed writer)

    @property
    def todo(self) -> list[str]:
        return [f for f in self.files if self.latest.get(f, {}).get("result") is None]


# ---------------------------------------------------------------------------- checking the arguments
def _jobs(text: str | None) -> int | None:
    try:
        return batch_exec.parse_jobs(text)
    except ValueError as exc:
        raise BatchError(str(exc)) from None


def _files(names: list[str]) -> list[str]:
    if not names:
        raise BatchError("no FILE given")
    bad = [n for n in names if not os.path.isfile(n)]
    if bad:
        why = ", ".join(
            f"{n} ({'not a regular file' if os.path.exists(n) else 'does not exist'})"
            for n in bad[:10]
        )
        raise BatchError(
            f"{len(bad)} FILE(s) cannot be read: {why}" + (" ..." if len(bad) > 10 else "")
        )
    return list(dict.fromkeys(os.path.abspath(n) for n in names))


def _extra(command: str, text: str, first_file: str) -> list[str]:
    try:
        extra = shlex.split(text)
    except ValueError as exc:
        raise BatchError(f"--args {text!r}: {exc}") from None
    try:
        args = batch_task.parse_command(command, first_file, extra)
    except ValueError as exc:
        raise BatchError(
            f"--args {text!r} for fbs {' '.join(batch_task.COMMANDS[command])}: {exc}"
        ) from None
    for dest in batch_task.SHARED_OUTPUTS.get(command, ()):
        if getattr(args, dest, None) is not None:
            raise BatchError(
                f"--args {text!r}: --{dest} would send every file's output to one place; "
                f"leave it out"
            )
    return extra


def _read_results(out: Path, plan: Plan) -> None:
    """Check an existing ``--out`` is a batch results file of this COMMAND and ``--args``, and
    note its newest line per file (a last line cut short by a killed writer is left out)."""
    try:
        lines, plan.torn_tail = batch_exec.read_results(out)
    except ValueError as exc:
        raise BatchError(
            f"--out {out} is not a batch results file ({exc}); give another --out"
        ) from None
    for n, rec in lines:
        missing = [
            k
            for k in batch_task.RECORD_KEYS
            if k != "args" and not (isinstance(rec, dict) and k in rec)
        ]
        if missing:
            raise BatchError(
                f"--out {out} is not a batch results file (line {n} has no {', '.join(missing)}); "
                f"give another --out"
            )
        if rec["command"] != plan.command:
            raise BatchError(
                f"--out {out} holds results of `fbs batch {rec['command']}`, not `fbs batch "
                f"{plan.command}`: give another --out"
            )
        if rec.get("args", []) != plan.extra:
            raise BatchError(
                f"--out {out} holds results made with --args {shlex.join(rec.get('args', []))!r}, "
                f"not {shlex.join(plan.extra)!r}: give the same --args, or another --out"
            )
        plan.latest[str(rec["file"])] = rec


def _out(text: str) -> Path:
    out = Path(text)
    if out.exists() or out.is_symlink():
        if not out.is_file():
            raise BatchError(f"--out {out} is not a regular file")
        if not os.access(out, os.R_OK | os.W_OK):
            raise BatchError(f"--out {out} cannot be read and written (permissions)")
    else:
        parent = out.parent
        if not parent.is_dir():
            raise BatchError(f"--out {out}: the directory {parent} does not exist")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise BatchError(f"--out {out}: the directory {parent} is not writable")
    return out


def plan_of(args: argparse.Namespace) -> Plan:
    """Every argument checked (``BatchError`` naming the bad value); nothing written."""
    command = args.batch_command
    if command not in batch_task.COMMANDS:
        raise BatchError(
            f"unknown COMMAND {command!r}; fbs batch runs {', '.join(batch_task.COMMANDS)}"
        )
    jobs = _jobs(args.jobs)
    files = _files(args.files)
    out = _out(args.out)
    if any(os.path.exists(out) and os.path.samefile(out, f) for f in files):
        raise BatchError(f"--out {out} is one of the FILEs")
    plan = Plan(
        command=command,
        extra=_extra(command, args.args, files[0]),
        files=files,
        out=out,
        jobs=jobs,
        scheduler=args.scheduler,
    )
    if out.exists():
        _read_results(out, plan)
    return plan


# ---------------------------------------------------------------------------- the run
def _say(text: str) -> None:
    print(f"fbs batch: {text}", file=sys.stderr, flush=True)


def _lost(plan: Plan, path: str, exc: BaseException) -> dict[str, Any]:
    """The line of a file whose worker failed it (not the command: the process or the cluster)."""
    return batch_task.record(
        path,
        plan.command,
        plan.extra,
        2,
        None,
        f"{batch_exec.lost_reason(exc)}; run the batch again to retry it",
        0.0,
    )


def _exit_code(plan: Plan) -> int:
    recs = [plan.latest[f] for f in plan.files if f in plan.latest]
    if len(recs) < len(plan.files) or any(
        r.get("error") is not None or r.get("exit") not in (0, 1) for r in recs
    ):
        return 2
    return 1 if any(r["exit"] == 1 for r in recs) else 0


def _run(plan: Plan, backend: batch_exec.Backend, results: batch_exec.ResultsFile) -> None:
    todo = plan.todo
    n_todo, n_done, n_err = len(todo), 0, 0
    t0 = time.monotonic()

    def done(path: str, rec: Any, exc: BaseException | None) -> None:
        nonlocal n_done, n_err
        if exc is not None:
            rec = _lost(plan, path, exc)
        results.append(rec)
        plan.latest[path] = rec
        n_err += rec["error"] is not None
        how = (
            "ok" if rec["error"] is None else f"exit {rec['exit']}: {rec['error'].splitlines()[-1]}"
        )
        n_done += 1
        _say(
            f"[{n_done}/{n_todo}] {path}: {how} ({rec['elapsed_s']:.1f} s); {n_err} error(s), "
            f"{time.monotonic() - t0:.0f} s elapsed"
        )

    def interrupted(n_done: int, n_in_flight: int, n_not_submitted: int) -> None:
        _say(
            f"interrupted: {n_done} result(s) of this run kept in {plan.out}, {n_in_flight} unfinished "
            f"cancelled, {n_not_submitted} not submitted; run the same command again to go on"
        )

    batch_exec.run_tasks(
        backend,
        batch_task.run_file,
        [(p, (plan.command, plan.extra, p)) for p in todo],
        done,
        interrupted,
    )


def _batch(args: argparse.Namespace) -> int:
    # every argument and the --out checked before anything is opened
    out = plan_of(args).out
    created = not out.exists()
    results = batch_exec.ResultsFile(out)
    try:
        # planned again with the results file held: what another batch wrote meanwhile counts
        plan = plan_of(args)
        results.cut(plan.torn_tail)
        todo = plan.todo
        done = len(plan.files) - len(todo)
        retried = sum(1 for f in todo if f in plan.latest)
        # no more local processes than files to run
        jobs = batch_exec.local_jobs(plan.jobs, plan.scheduler, len(todo))
        backend = batch_exec.open_backend(jobs, plan.scheduler) if todo else None
    except BaseException:
        results.close()
        if (
            created and out.stat().st_size == 0
        ):  # refused (a backend that cannot start): no file left behind
            out.unlink()
        raise
    try:
        if plan.torn_tail:
            _say(
                f"dropped an unfinished last line ({plan.torn_tail} bytes) a killed batch left in {plan.out}"
            )
        _say(
            f"{plan.command} on {len(plan.files)} file(s): {done} already done in {plan.out} (skipped)"
            + (f", {retried} earlier error(s) retried" if retried else "")
            + (f"; {len(todo)} to run on {backend.describe()}" if backend else "; nothing to run")
        )
        if backend:
            try:
                _run(plan, backend, results)
            finally:
                backend.close()
    finally:
        results.close()
    code = _exit_code(plan)
    errors = sum(1 for f in plan.files if plan.latest.get(f, {}).get("error") is not None)
    _say(f"{len(plan.files)} file(s), {errors} with an error; results in {plan.out}; exit {code}")
    return code


def add_parser(sub: argparse._SubParsersAction) -> None:
    b = sub.add_parser(
        "batch",
        help="one analysis command on many run files, in parallel (local processes or a "
        "Dask cluster), one JSON result line per file",
        description="Runs COMMAND on every FILE as `fbs COMMAND FILE --json OPTIONS` would, in "
        "parallel, and appends one JSON line per file to --out as each finishes; an interrupted batch "
        "goes on where it stopped when run again. Exit 0 all ok, 1 some file's limits failed, 2 some "
        "file failed (or interrupted, or refused).",
    )
    b.add_argument(
        "batch_command", metavar="COMMAND", help=f"one of {', '.join(batch_task.COMMANDS)}"
    )
    b.add_argument(
        "files",
        nargs="*",
        metavar="FILE",
        help="fbs-run files (finished ones, on storage every worker reads)",
    )
    b.add_argument(
        "--out",
        required=True,
        metavar="RESULTS.jsonl",
        help="results, one JSON line per file; an existing one of the same COMMAND is resumed",
    )
    b.add_argument(
        "--jobs",
        metavar="N",
        help="local processes (default: one per core); with --scheduler, the "
        "most files in flight at once (default: all)",
    )
    b.add_argument(
        "--scheduler",
        metavar="ADDR",
        help="a Dask distributed scheduler, e.g. tcp://host:8786 "
        f"(needs {batch_exec.CLUSTER_EXTRA})",
    )
    b.add_argument(
        "--args",
        default="",
        metavar="'OPTIONS'",
        help="options for COMMAND, as one word: e.g. --args='--axis X --seed 2'",
    )
    b.set_defaults(func=_batch)
