"""Where ``fbs batch`` runs its files: a local process pool, or a Dask distributed cluster.

Both are a ``concurrent.futures.Executor`` to the batch loop (``fbs.batch``), which submits
``fbs.batch_task.run_file`` and writes each result as it arrives; only starting, describing
and stopping differ.

- ``LocalPool``: ``ProcessPoolExecutor`` of spawned processes. Their environment is set in this
  process before they start (spawned children inherit it, so it holds before numpy loads in
  them): one BLAS thread each and the user's numba cache (``batch_task.worker_environment``).
  Workers ignore SIGINT and SIGHUP: the batch process handles those, and ends its workers.
  A worker that dies (a crash, the OOM killer) breaks a ``ProcessPoolExecutor``: the files in
  flight are recorded as errors (retried by the next run) and a fresh pool takes the rest.
- ``DaskCluster``: ``distributed.Client(ADDR).get_executor()``. The cluster's workers must have
  fbs-hil installed; a worker lost mid-file has its file rescheduled by the scheduler on another.
  ``distributed`` is the optional extra ``fbs-hil[cluster]``.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from fbs import batch_task

CLUSTER_EXTRA = "pip install 'fbs-hil[cluster]'"
#: seconds to wait for the scheduler to answer (connecting, not the work)
CONNECT_TIMEOUT_S = 30


class BackendError(ValueError):
    """The executor cannot be started (no ``distributed``, no scheduler at the address)."""


def _init_local_worker() -> None:
    for s in (getattr(signal, n, None) for n in ("SIGINT", "SIGHUP")):
        if s is not None:
            signal.signal(s, signal.SIG_IGN)
    batch_task.prepare_process()


class LocalPool:
    """``jobs`` spawned processes on this machine."""

    def __init__(self, jobs: int) -> None:
        self.jobs = jobs
        self.max_in_flight = jobs           # no queue behind the workers: a broken pool loses no queued file
        env = batch_task.worker_environment()
        self._saved = {k: os.environ.get(k) for k in env}
        os.environ.update(env)              # inherited by the workers the pool spawns
        self._pool = self._new_pool()

    def _new_pool(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(self.jobs, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=_init_local_worker)

    def describe(self) -> str:
        return f"{self.jobs} local process{'es' if self.jobs != 1 else ''} (one BLAS thread each)"

    def submit(self, *args: Any) -> Future[dict[str, Any]]:
        try:
            return self._pool.submit(batch_task.run_file, *args)
        except BrokenProcessPool:          # a worker died: its files are recorded as errors; go on afresh
            self._pool.shutdown(wait=True)
            self._pool = self._new_pool()
            return self._pool.submit(batch_task.run_file, *args)

    def abort(self) -> None:
        """Cancel what has not started and end the workers (what they were doing is lost)."""
        self._pool.shutdown(wait=False, cancel_futures=True)
        for p in multiprocessing.active_children():     # this process's pool workers
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
            raise BackendError(f"--scheduler needs Dask's distributed, an optional dependency that is not installed "
                               f"here ({exc}): {CLUSTER_EXTRA}") from None
        try:
            self._client = distributed.Client(address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
        except (OSError, TimeoutError, ValueError, TypeError) as exc:
            raise BackendError(f"--scheduler {address}: cannot connect ({type(exc).__name__}: {exc})") from None
        self.address = address
        self.max_in_flight = jobs if jobs is not None else 1 << 30    # all at once unless --jobs caps it
        self._executor: Executor = self._client.get_executor(pure=False)

    def describe(self) -> str:
        threads = self._client.nthreads()
        return (f"Dask scheduler {self.address} ({len(threads)} worker{'s' if len(threads) != 1 else ''}, "
                f"{sum(threads.values())} threads)")

    def submit(self, *args: Any) -> Future[dict[str, Any]]:
        return self._executor.submit(batch_task.run_file, *args)

    def abort(self) -> None:
        self._executor.shutdown(wait=False)      # cancels every future not finished
        self._client.close()

    def close(self) -> None:
        self._client.close()


Backend = LocalPool | DaskCluster


def open_backend(jobs: int | None, scheduler: str | None) -> Backend:
    """The executor ``fbs batch`` asked for (``jobs`` None: one process per core available)."""
    if scheduler:
        return DaskCluster(scheduler, jobs)
    return LocalPool(jobs if jobs is not None else default_jobs())


def default_jobs() -> int:
    """The cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:          # not Linux
        return max(1, os.cpu_count() or 1)
