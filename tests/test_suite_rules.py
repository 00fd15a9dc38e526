"""The suite's own rules (issue 40 item 6): a hang guard on every test, markers spelled right,
lines short enough to read."""

from __future__ import annotations

import subprocess
from pathlib import Path


def test_every_test_has_a_hang_guard_and_markers_are_strict(pytestconfig):
    assert (
        0 < float(pytestconfig.getini("timeout")) <= 3600
    )  # pytest-timeout: a guard, not a deadline
    assert "--strict-markers" in pytestconfig.getini("addopts")


def test_lines_are_short_enough_to_read_side_by_side():
    """`ruff format` wraps code at 100 characters (`make check` runs `ruff format --check`); what
    it cannot wrap - a long string or comment - may run to 120 (ruff's E501). At most 1.5 % of the
    lines over 100, as the projects we read side by side keep."""
    root = Path(__file__).resolve().parents[1]
    files = subprocess.run(
        ["git", "ls-files", "*.py"], cwd=root, capture_output=True, text=True, check=True
    ).stdout.split()
    lines = [ln for f in files for ln in (root / f).read_text().splitlines()]
    long = [ln for ln in lines if len(ln) > 100]
    assert len(long) <= 0.015 * len(lines), f"{len(long)} of {len(lines)} lines over 100"


def test_a_warning_is_a_failure_unless_named(pytestconfig):
    assert "error" in pytestconfig.getini("filterwarnings")
