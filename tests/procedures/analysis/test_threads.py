from __future__ import annotations

import os

import pytest

from procedures.analysis.threads import analysis_threads


@pytest.mark.parametrize("value, expect", [("3", 3), (" 1 ", 1)])
def test_omp_num_threads_sets_the_count(monkeypatch, value, expect):
    monkeypatch.setenv("OMP_NUM_THREADS", value)
    assert analysis_threads() == expect


@pytest.mark.parametrize("value", [None, "", "0", "two", "-2"])
def test_otherwise_the_cores_this_process_may_use(monkeypatch, value):
    if value is None:
        monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("OMP_NUM_THREADS", value)
    assert analysis_threads() == len(os.sched_getaffinity(0))
