"""Fixtures every test folder may use."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import settings

import drivers.safety
from fbs.batch_task import BLAS_THREAD_VARS, limit_loaded_blas

# Every run of the suite draws the same hypothesis examples: CI starts from a fresh clone (no
# example database), and a verdict must not depend on which examples a run happened to draw.
# No deadline: hypothesis's 200 ms per example is a wall-clock limit, and on a busy box a
# matplotlib label took 261 ms once (a "FlakyFailure" that said nothing of the code).
settings.register_profile("fbs", derandomize=True, deadline=None)
settings.load_profile("fbs")


def pytest_configure(config):
    """One BLAS thread in each process of the suite, as in a batch worker (``fbs.batch_task``):
    `make test` runs a worker per core and one more, and OpenBLAS's own threads on a core another
    worker holds wait for each other (a 2160x39x44 complex product of the gap model took 8 ms
    so, 0.8 ms with one thread, on a busy 2-core box). Set before the xdist workers and the `fbs`
    processes of the tests start, and held for the libraries this process has loaded."""
    for var in BLAS_THREAD_VARS:
        os.environ.setdefault(var, "1")
    limit_loaded_blas()


def pytest_collection_modifyitems(config, items):
    """For ``make test``'s ``pytest -n N --dist loadfile`` (a file to a worker, so a module
    fixture is made once): the files with end-to-end runs on the sim rig (``slow``) first, so
    the long ones start at once and the short ones fill in around them, instead of one long
    file starting last and running alone. Within a file, the order is the file's."""
    slow_files = {
        item.nodeid.split("::", 1)[0] for item in items if item.get_closest_marker("slow")
    }

    def rank(item) -> tuple[int, int]:
        f = item.nodeid.split("::", 1)[0]
        longest = next(
            (i for i, name in enumerate(LONGEST_FILES) if f.endswith(name)), len(LONGEST_FILES)
        )
        return (f not in slow_files, longest)

    items.sort(key=rank)  # stable: within a file, the file's order


#: the files with the most work (a fresh-clone run's durations): they start first, so no long one
#: starts last and runs alone (the unit-variation fixture, 6 min, once ended a run 8 min late)
LONGEST_FILES = (
    "procedures/test_earth_rate_stopwatch.py",
    "procedures/test_stopwatch_resume.py",
    "gap/test_unit_variation.py",
    "fbs/test_campaign.py",
    "fbs/test_batch.py",
    "fbs/test_cli_run.py",
    "gap/test_hidden_effects.py",
    "procedures/test_excitation.py",
    "procedures/test_excitation_modes.py",
)


@pytest.fixture
def go_safe_calls(monkeypatch):
    """The reasons ``drivers.safety.go_safe`` was called with, in order. It is wrapped, not
    replaced: each call still drives the rig safe, so a test sees both the call and its effect."""
    calls: list[str] = []
    real = drivers.safety.go_safe

    def spy(rig, why):
        calls.append(why)
        return real(rig, why)

    monkeypatch.setattr(drivers.safety, "go_safe", spy)
    return calls


class SmallDisk:
    """A real small filesystem (tmpfs) of its own for a test: the full disk the world makes,
    not a file-size limit."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def free(self) -> int:
        return shutil.disk_usage(self.path).free

    def fill(self, leave_bytes: int = 0) -> None:
        """Take all but ``leave_bytes`` of the free space (as another program would)."""
        with open(self.path / f"ballast{len(list(self.path.glob('ballast*')))}", "wb") as fh:
            want = max(0, self.free() - leave_bytes)
            block = bytes(1 << 16)
            while want > 0:
                try:
                    want -= fh.write(block[: min(want, len(block))])
                    fh.flush()
                except OSError:  # what is left is smaller than a block: full is full
                    break


@pytest.fixture
def small_disk(tmp_path):
    """``small_disk(size_bytes)`` mounts a tmpfs of that size and returns a ``SmallDisk``;
    unmounted after the test. Skipped, with the reason, where this machine does not let the
    tests mount one (not root, or no CAP_SYS_ADMIN in a container)."""
    mounted: list[Path] = []

    def make(size_bytes: int) -> SmallDisk:
        if (
            not sys.platform.startswith("linux")
            or os.geteuid() != 0
            or shutil.which("mount") is None
        ):
            pytest.skip(
                "mounting a small tmpfs needs Linux, root and mount(8); this machine has not all three"
            )
        d = tmp_path / f"disk{len(mounted)}"
        d.mkdir()
        p = subprocess.run(
            ["mount", "-t", "tmpfs", "-o", f"size={int(size_bytes)},mode=1777", "tmpfs", str(d)],
            capture_output=True,
            text=True,
        )
        if p.returncode:
            pytest.skip(f"cannot mount a small tmpfs here: {p.stderr.strip() or p.returncode}")
        mounted.append(d)
        return SmallDisk(d)

    yield make
    for d in mounted:
        subprocess.run(["umount", "-l", str(d)], capture_output=True)
