"""One file of ``fbs batch``, as a worker runs it: the command's own code path, in-process.

``run_file(command, extra, path)`` parses ``fbs <command words> PATH --json <extra>`` with the
``fbs`` parser itself and calls the function the command's ``--json`` prints
(``json_result``, set on its subparser), so a batch result is exactly what the single command
prints. It never raises for the file's sake: the command's errors become the record's
``exit`` 2 and ``error``, as ``fbs.cli.main`` reports them; anything else (a bug) is exit 2
with "internal error" and its traceback, as the single command ends (``guarded``, which
``fbs.campaign_task`` ends its runs with too); a result whose verdict is "fail" is exit 1.

A worker runs with one BLAS thread (``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS``,
``MKL_NUM_THREADS`` = 1, and threadpoolctl where installed) and numba's cache in a directory of
the user's own (``NUMBA_CACHE_DIR``, default ``$XDG_CACHE_HOME/fbs-hil/numba``): several
processes that each start as many BLAS threads as cores run slower together than one process
alone, and a checkout shared by several users is not everyone's to write its ``__pycache__``.

This module imports no numerics at import time, so a worker can set its environment before
numpy and numba load.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

#: ``fbs batch COMMAND``: the ``fbs`` words before FILE
COMMANDS: dict[str, tuple[str, ...]] = {
    "gap": ("gap",),
    "inspect": ("inspect",),
    "spectra": ("spectra",),
    "analyze-hysteresis": ("analyze", "hysteresis"),
    "analyze-transfer": ("analyze", "transfer"),
}
#: options that name one output place for every file: refused, the files would overwrite each other's
SHARED_OUTPUTS: dict[str, tuple[str, ...]] = {
    "gap": ("report",),
    "spectra": ("out",),
    "analyze-hysteresis": ("out",),
    "analyze-transfer": ("out",),
}
#: the environment variables that hold a worker's BLAS to one thread
BLAS_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
#: the keys of a result line, in order
RECORD_KEYS = ("file", "command", "args", "exit", "result", "error", "elapsed_s")


def numba_cache_dir() -> str:
    """``NUMBA_CACHE_DIR`` if set, else the user's own ``$XDG_CACHE_HOME/fbs-hil/numba``."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return os.environ["NUMBA_CACHE_DIR"]
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return str(Path(base) / "fbs-hil" / "numba")


def worker_environment() -> dict[str, str]:
    """The variables a worker process runs with (set before numpy and numba are imported)."""
    return {**dict.fromkeys(BLAS_THREAD_VARS, "1"), "NUMBA_CACHE_DIR": numba_cache_dir()}


def prepare_process() -> None:
    """Set ``worker_environment()`` in this process. Takes effect for the BLAS and numba loaded
    after it; ``limit_loaded_blas`` holds the ones already loaded."""
    os.environ.update(worker_environment())


def limit_loaded_blas() -> None:
    """One thread for every BLAS/OpenMP library loaded in this process (threadpoolctl, where installed)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # the environment variables set before numpy was loaded do it
        return
    threadpool_limits(limits=1)


def command_argv(command: str, path: str, extra: list[str]) -> list[str]:
    """The single command ``fbs batch COMMAND`` runs on ``path``."""
    return [*COMMANDS[command], path, "--json", *extra]


def parse_command(command: str, path: str, extra: list[str]) -> argparse.Namespace:
    """``fbs``'s own parse of ``command_argv``. Raises ``ValueError`` with argparse's message
    for options the command does not take, and for a command without a ``--json`` result."""
    from fbs.cli import build_parser

    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            args = build_parser().parse_args(command_argv(command, path, extra))
    except SystemExit as exc:
        lines = [ln for ln in err.getvalue().splitlines() if ln.strip()]
        raise ValueError(lines[-1] if lines else f"argparse exit {exc.code}") from None
    if not callable(getattr(args, "json_result", None)):
        raise ValueError(f"fbs {' '.join(COMMANDS[command])} has no --json result to collect")
    return args


def record(
    path: str,
    command: str,
    extra: list[str],
    exit_code: int,
    result: Any,
    error: str | None,
    elapsed_s: float,
) -> dict[str, Any]:
    """One line of the results file."""
    return dict(
        zip(
            RECORD_KEYS, (path, command, list(extra), exit_code, result, error, round(elapsed_s, 3))
        )
    )


def guarded(fn: Callable[..., Any], *args: Any) -> tuple[int, Any, str | None, float]:
    """``fn(*args)`` ended as a single command ends: ``(exit, result, error, seconds)``, with exit
    0 and the result; 2 and the message for ``fbs.cli.command_errors()`` (what ``fbs CMD`` reports
    as ``error: ...``); 1 and the traceback for anything else (a bug). It never raises for the
    task's sake (``KeyboardInterrupt`` and ``SystemExit`` go on up)."""
    from fbs.cli import command_errors

    t0 = time.perf_counter()
    try:
        result = fn(*args)
    except command_errors() as exc:
        return 2, None, str(exc), time.perf_counter() - t0
    except Exception as exc:  # a bug: the single command says "internal error", exit 2
        text = "".join(traceback.format_exception(exc)).rstrip()
        return (
            2,
            None,
            f"internal error: {type(exc).__name__}: {exc}\n{text}",
            time.perf_counter() - t0,
        )
    return verdict_exit(result), result, None, time.perf_counter() - t0


def verdict_exit(result: Any) -> int:
    """The exit code the single command gives a result: 1 for a verdict "fail" (limits failed,
    or no headline figure measured), 2 for "aborted"/"error", else 0."""
    verdict = result.get("verdict") if isinstance(result, dict) else None
    return {"fail": 1, "aborted": 2, "error": 2}.get(verdict, 0) if isinstance(verdict, str) else 0


def _json_of(command: str, path: str, extra: list[str]) -> Any:
    args = parse_command(command, path, extra)
    # what the single command prints, read back: the batch holds exactly that object
    return json.loads(json.dumps(args.json_result(args)))


def run_file(command: str, extra: list[str], path: str) -> dict[str, Any]:
    """``fbs <command> path --json <extra>`` in this process, as a result line."""
    prepare_process()
    # the first file of a process loads the command's numerics here, not counted in its elapsed_s
    from fbs.cli import load

    load(COMMANDS[command][0])

    limit_loaded_blas()
    code, result, error, elapsed = guarded(_json_of, command, path, extra)
    return record(path, command, extra, code, result, error, elapsed)
