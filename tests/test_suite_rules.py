"""The suite's own rules (issue 40 item 6): a hang guard on every test, markers spelled right."""

from __future__ import annotations


def test_every_test_has_a_hang_guard_and_markers_are_strict(pytestconfig):
    assert 0 < float(pytestconfig.getini("timeout")) <= 3600     # pytest-timeout: a guard, not a deadline
    assert "--strict-markers" in pytestconfig.getini("addopts")

