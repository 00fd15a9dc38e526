"""Where ``fbs batch`` and ``fbs campaign`` run their work: a local process pool, or a Dask
distributed cluster; and what both do around it (the loop that submits and collects, the
results file appended one whole line at a time, reading it back to resume).

Both executors are a ``concurrent.futures.Executor`` to ``run_tasks``, which submits a
module-level function (``fbs.batch_task.run_file``, ``fbs.campaign_task.run``) and hands each
result to its caller as it arrives; only starting, describing and stopping differ.

- ``LocalPool``: ``ProcessPoolExecutor`` of spawned processes. Their environment is set in this
  process before they start (spawned children inherit it, so it holds before numpy loads in
  them): one BLAS thread each and the user's numba cache (``batch_task.worker_environment``).
  Workers ignore SIGINT and SIGHUP: the calling process handles those, and ends its workers.
  A worker that dies (a crash, the OOM killer) breaks a ``ProcessPoolExecutor``: the tasks in
  flight fail with ``BrokenProcessPool`` (recorded as errors, or submitted again where the
  caller allows it) and a fresh pool takes the rest.
- ``DaskCluster``: ``distributed.Client(ADDR).get_executor()``. The cluster's workers must have
  fbs-hil installed; a worker lost mid-task has its task rescheduled by the scheduler on another.
  ``distributed`` is the optional extra ``fbs-hil[cluster]``.
"""

from __future__ import annotations

import fcntl
import json
import multiprocessing
import os
import re
import signal
import socket
from collections import deque
from collections.abc import Callable, Hashable, Iterable
from concurrent.futures import (
    FIRST_COMPLETED,
    CancelledError,
    Executor,
    Future,
    ProcessPoolExecutor,
    wait,
)
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any, TypeVar

from fbs import batch_task, jsonout
from procedures.analysis.threads import usable_cores
from procedures.held_signals import signals_held

CLUSTER_EXTRA = "pip install 'fbs-hil[cluster]'"
#: seconds to wait for the scheduler to answer (connecting, not the work)
CONNECT_TIMEOUT_S = 30

K = TypeVar("K", bound=Hashable)


class BackendError(ValueError):
    """The executor cannot be started (no ``distributed``, no scheduler at the address)."""


# ---------------------------------------------------------------------------- the executors
#: a scheduler address: ``[tcp|tls://]host:port`` (an IPv6 host in brackets)
_ADDRESS = re.compile(
    r"^(?:(?P<scheme>tcp|tls)://)?(?P<host>\[[0-9a-fA-F:.]+\]|[A-Za-z0-9.-]+):(?P<port>\d{1,5})$"
)


def check_scheduler_address(address: str) -> None:
    """Refuse an address that names no scheduler (``BackendError`` with the form it must have),
    and, over TCP, one where nothing answers within ``CONNECT_TIMEOUT_S``."""
    m = _ADDRESS.match(address)
    if m is None or not 1 <= int(m["port"]) <= 65535:
        raise BackendError(
            f"--scheduler {address!r} must be a Dask scheduler address [tcp://]HOST:PORT, port "
            f"1..65535, e.g. tcp://127.0.0.1:8786"
        )
    host = m["host"].strip("[]")
    try:
        socket.create_connection((host, int(m["port"])), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        raise BackendError(
            f"--scheduler {address}: nothing answers there ({exc.strerror or exc})"
        ) from None


def _init_local_worker() -> None:
    for s in (getattr(signal, n, None) for n in ("SIGINT", "SIGHUP")):
        if s is not None:
            signal.signal(s, signal.SIG_IGN)
    batch_task.prepare_process()


class LocalPool:
    """``jobs`` spawned processes on this machine."""

    def __init__(self, jobs: int) -> None:
        self.jobs = jobs
        self.max_in_flight = jobs  # no queue behind the workers: a broken pool loses no queued task
        env = batch_task.worker_environment()
        self._saved = {k: os.environ.get(k) for k in env}
        os.environ.update(env)  # inherited by the workers the pool spawns
        self._pool = self._new_pool()

    def _new_pool(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(
            self.jobs,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_init_local_worker,
        )

    def describe(self) -> str:
        return f"{self.jobs} local process{'es' if self.jobs != 1 else ''} (one BLAS thread each)"

    def submit(self, fn: Callable[..., Any], *args: Any) -> Future[Any]:
        try:
            return self._pool.submit(fn, *args)
        except BrokenProcessPool:  # a worker died: its tasks failed with it; go on afresh
            self._pool.shutdown(wait=True)
            self._pool = self._new_pool()
            return self._pool.submit(fn, *args)

    def abort(self) -> None:
        """Cancel what has not started and end the workers (what they were doing is lost)."""
        self._pool.shutdown(wait=False, cancel_futures=True)
        for p in multiprocessing.active_children():  # this process's pool workers
            p.terminate()
        self._pool.shutdown(wait=True)

    def close(self) -> None:
        self._pool.shutdown(wait=True)
        for k, v in self._saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class DaskCluster:
    """The workers of the Dask scheduler at ``address``."""

    def __init__(self, address: str, jobs: int | None) -> None:
        try:
            import distributed
        except ImportError as exc:
            raise BackendError(
                f"--scheduler needs Dask's distributed, an optional dependency that is not installed "
                f"here ({exc}): {CLUSTER_EXTRA}"
            ) from None
        # A Client that fails in its constructor still closes itself when collected, waiting 60 s
        # and printing a traceback at exit: an address that cannot work is refused before one is made.
        check_scheduler_address(address)
        try:
            self._client = distributed.Client(
                address, timeout=CONNECT_TIMEOUT_S, set_as_default=False
            )
        except (OSError, TimeoutError, ValueError, TypeError) as exc:
            raise BackendError(
                f"--scheduler {address}: cannot connect ({type(exc).__name__}: {exc})"
            ) from None
        self.address = address
        self.max_in_flight = (
            jobs if jobs is not None else 1 << 30
        )  # all at once unless --jobs caps it
        self._executor: Executor = self._client.get_executor(pure=False)

    def describe(self) -> str:
        threads = self._client.nthreads()
        return (
            f"Dask scheduler {self.address} ({len(threads)} worker{'s' if len(threads) != 1 else ''}, "
            f"{sum(threads.values())} threads)"
        )

    def submit(self, fn: Callable[..., Any], *args: Any) -> Future[Any]:
        return self._executor.submit(fn, *args)

    def abort(self) -> None:
        self._executor.shutdown(wait=False)  # cancels every future not finished
        self._client.close()

    def close(self) -> None:
        self._client.close()


Backend = LocalPool | DaskCluster


def open_backend(jobs: int | None, scheduler: str | None) -> Backend:
    """The executor asked for (``jobs`` None: one process per core available)."""
    if scheduler:
        return DaskCluster(scheduler, jobs)
    return LocalPool(jobs if jobs is not None else usable_cores())


def parse_jobs(text: str | None) -> int | None:
    """``--jobs``: None (not given) or a whole number >= 1; ``ValueError`` naming the value."""
    if text is None:
        return None
    try:
        jobs = int(text)
    except ValueError:
        raise ValueError(f"--jobs {text!r} is not a whole number") from None
    if jobs < 1:
        raise ValueError(f"--jobs {text!r} must be at least 1")
    return jobs


def local_jobs(jobs: int | None, scheduler: str | None, n_tasks: int) -> int | None:
    """The ``jobs`` to open a backend with: on a cluster as given; locally no more processes than
    tasks (default one per core)."""
    return jobs if scheduler else min(jobs or usable_cores(), max(1, n_tasks))


# ---------------------------------------------------------------------------- submitting and collecting
def lost_reason(exc: BaseException) -> str:
    """Why a task has no result when the executor, not the task, failed it."""
    why = (
        "its worker process died"
        if isinstance(exc, BrokenProcessPool)
        else "its executor failed it"
    )
    return f"{why} ({type(exc).__name__}: {exc})"


def run_tasks(
    backend: Backend,
    fn: Callable[..., Any],
    tasks: Iterable[tuple[K, tuple[Any, ...]]],
    done: Callable[[K, Any, BaseException | None], None],
    interrupted: Callable[[int, int, int], None],
    *,
    retry_lost: int = 0,
    retrying: Callable[[K, BaseException], None] | None = None,
) -> None:
    """``fn(*args)`` for every ``(key, args)`` of ``tasks`` on ``backend``, at most
    ``backend.max_in_flight`` at once; ``done(key, result, None)`` as each finishes, in this
    thread, or ``done(key, None, exc)`` for a task the executor failed (its worker process died,
    the cluster gave up on it). A task whose local worker died is first submitted again, up to
    ``retry_lost`` times (a worker killed under other tasks takes theirs down with it), and
    ``retrying(key, exc)`` told.

    On ``KeyboardInterrupt`` (the abort signals, ``fbs.signals``): nothing more is submitted,
    the backend is aborted (unstarted tasks cancelled, local workers ended), then
    ``interrupted(n_done, n_in_flight, n_not_submitted)`` is called, with the abort signals
    held, and the interrupt goes on up."""
    todo: deque[tuple[K, tuple[Any, ...]]] = deque(tasks)
    in_flight: dict[Future[Any], tuple[K, tuple[Any, ...]]] = {}
    retries: dict[K, int] = {}
    n_done = 0
    try:
        while todo or in_flight:
            while todo and len(in_flight) < backend.max_in_flight:
                key, args = todo.popleft()
                in_flight[backend.submit(fn, *args)] = (key, args)
            finished, _ = wait(in_flight, timeout=5.0, return_when=FIRST_COMPLETED)
            for fut in finished:
                key, args = in_flight.pop(fut)
                try:
                    exc = fut.exception()
                except (
                    CancelledError
                ) as cancelled:  # by the cluster (a scheduler restarted), not by us
                    exc = cancelled
                if isinstance(exc, BrokenProcessPool) and retries.get(key, 0) < retry_lost:
                    retries[key] = retries.get(key, 0) + 1
                    todo.appendleft((key, args))
                    if retrying is not None:
                        retrying(key, exc)
                    continue
                done(key, None if exc is not None else fut.result(), exc)
                n_done += 1
    except KeyboardInterrupt:
        with signals_held():  # a second signal does not cut the stopping short
            backend.abort()
            interrupted(n_done, len(in_flight), len(todo))
        raise


# ---------------------------------------------------------------------------- the results file
class ResultsBusy(ValueError):
    """Another batch holds the results file (a ``ValueError``: refused, exit 2)."""


class ResultsFile:
    """A JSON-lines results file, appended one whole line per result and synced to disk, held
    by one batch at a time (an exclusive ``flock`` for as long as it is open: a second batch on
    the same ``--out`` is refused, ``ResultsBusy``, instead of mixing its lines in)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(self._fd)
            raise ResultsBusy(
                f"--out {path} is being written by another `fbs batch` now: wait for it to end "
                f"(then run again to resume), or give another --out"
            ) from None

    def cut(self, torn_tail: int) -> None:
        """Cut off an unfinished last line (``torn_tail`` bytes, from ``read_results``)."""
        if torn_tail:
            os.ftruncate(self._fd, os.fstat(self._fd).st_size - torn_tail)

    def append(self, rec: dict[str, Any]) -> None:
        data = (jsonout.dumps(rec) + "\n").encode("utf-8")
        with signals_held():
            view = memoryview(data)
            while view:
                view = view[os.write(self._fd, view) :]
            os.fsync(self._fd)

    def close(self) -> None:
        os.close(self._fd)


def read_results(path: Path) -> tuple[list[tuple[int, Any]], int]:
    """The whole lines of a JSON-lines results file as ``(line number, object)``, blank lines
    left out, and the length in bytes of an unfinished last line (only a killed writer leaves
    one; it is not returned). ``ValueError("line N is not JSON")`` for the first line that is not."""
    raw = path.read_bytes()
    body, torn = raw, 0
    if raw and not raw.endswith(b"\n"):
        cut = raw.rfind(b"\n") + 1
        body, torn = raw[:cut], len(raw) - cut
    lines = []
    for n, line in enumerate(body.splitlines(), 1):
        if not line.strip():
            continue
        try:
            lines.append((n, json.loads(line.decode("utf-8"))))
        except (UnicodeDecodeError, ValueError):
            raise ValueError(f"line {n} is not JSON") from None
    return lines, torn
