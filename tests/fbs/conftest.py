"""Fixtures shared by the ``fbs`` command tests.

``cluster``: a real Dask cluster on localhost for ``fbs batch`` and ``fbs campaign``
(``--scheduler``): a ``dask scheduler`` and two ``dask worker`` processes, one thread each,
started for the test and ended after it (skipped where ``distributed`` is not installed).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

HANG_S = 180  # a hang guard, not a timing assertion


class Cluster:
    """A ``dask scheduler`` and two ``dask worker`` processes (one thread each), each in a
    process group of its own so that a test can kill a worker with its nanny."""

    def __init__(self, root: Path) -> None:
        pytest.importorskip("distributed")
        self.root, self.procs = root, []
        sched_file = root / "scheduler.json"
        self._start(
            "scheduler",
            "distributed.cli.dask_scheduler",
            "--host",
            "127.0.0.1",
            "--port",
            "0",
            "--no-dashboard",
            "--scheduler-file",
            str(sched_file),
        )
        t_end = time.monotonic() + HANG_S
        while not (sched_file.exists() and sched_file.read_text().strip().endswith("}")):
            assert time.monotonic() < t_end and self.procs[0].poll() is None, self.log("scheduler")
            time.sleep(0.1)
        self.address = json.loads(sched_file.read_text())["address"]
        self.workers = [
            self._start(
                f"worker{i}",
                "distributed.cli.dask_worker",
                self.address,
                "--host",
                "127.0.0.1",
                "--nthreads",
                "1",
                "--no-dashboard",
                "--name",
                f"w{i}",
            )
            for i in (1, 2)
        ]
        self.wait_for_workers(2)

    def _start(self, name: str, module: str, *args: str) -> subprocess.Popen:
        with open(self.root / f"{name}.log", "w") as log:  # the child has its own copy
            p = subprocess.Popen(
                [sys.executable, "-m", module, *args],
                stdout=log,
                stderr=subprocess.STDOUT,
                cwd=self.root,
                start_new_session=True,
            )
        self.procs.append(p)
        return p

    def log(self, name: str) -> str:
        return (self.root / f"{name}.log").read_text()

    def wait_for_workers(self, n: int) -> None:
        import distributed

        with distributed.Client(self.address, timeout=HANG_S, set_as_default=False) as c:
            c.wait_for_workers(n, timeout=HANG_S)

    def n_workers(self) -> int:
        import distributed

        with distributed.Client(self.address, timeout=HANG_S, set_as_default=False) as c:
            return len(c.nthreads())

    def kill(self, p: subprocess.Popen, sig: int = signal.SIGKILL) -> None:
        if p.poll() is None:
            try:
                os.killpg(p.pid, sig)
            except ProcessLookupError:
                pass

    def close(self) -> None:
        for p in reversed(self.procs):  # workers first, then the scheduler
            self.kill(p, signal.SIGTERM)
        for p in reversed(self.procs):
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.kill(p)
                p.wait(timeout=30)


@pytest.fixture
def cluster(tmp_path):
    c = Cluster(tmp_path)
    try:
        yield c
    finally:
        c.close()
