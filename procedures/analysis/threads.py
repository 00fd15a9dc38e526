"""How many threads an analysis may fan its independent fits out over.

The compiled kernels of a fit (``dahl._dahl_path``, ``dahl._filtfilt``) release the GIL, so
independent fits (a jackknife's replicates) run side by side on threads. The count follows the
convention the BLAS libraries keep: ``OMP_NUM_THREADS`` where it is set (``fbs batch``'s workers
and the test suite set 1: they already have a process per core), else the cores this process may
run on. The replicates' results do not depend on it: each is the same computation, collected in
order.
"""

from __future__ import annotations

import os


def analysis_threads() -> int:
    """Threads for independent fits: ``OMP_NUM_THREADS`` if set to a whole number >= 1, else the
    cores usable by this process."""
    text = os.environ.get("OMP_NUM_THREADS", "").strip()
    if text.isdigit() and int(text) >= 1:
        return int(text)
    return usable_cores()


def usable_cores() -> int:
    """The cores this process may run on (its affinity where the OS says, else the machine's)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)
