"""Issue 37 item 4, acceptance B: ``fbs run``'s progress lines on a pipe never go back and
name the analysis. A stopwatch run on a cold sim rig (its mode 3 step spins the wheels up, so
that step takes rig time): the old runner counted that step twice at its end (73 % in the
issue's run) and then fell back at the next step's start (46 %), and stood at 100 % while it
analysed and wrote the report."""

from __future__ import annotations

import re
import subprocess

import pytest

from tests.fbs.commands import FBS, SHORT_STOPWATCH

pytestmark = pytest.mark.slow

#: cold (no ``warm=1``), so mode 3 takes rig time
SHORT_COLD_STOPWATCH = ["--rig", "sim?seed=5&watchdog=5", *SHORT_STOPWATCH]
LINE = re.compile(r"fbs\.run_progress: stopwatch: +(\d+) %, (.*)$")


def test_the_progress_lines_of_a_run_never_go_back_and_show_the_analysis(tmp_path):
    r = subprocess.run(
        [*FBS, "run", "stopwatch", "--out", str(tmp_path), *SHORT_COLD_STOPWATCH],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode in (0, 1), r.stderr  # stderr is a pipe: plain lines
    lines = [(int(m[1]), m[2]) for m in map(LINE.search, r.stderr.splitlines()) if m]
    percents = [p for p, _ in lines]
    assert len(lines) > 5 and all(b >= a for a, b in zip(percents, percents[1:])), lines
    assert any(what.startswith("step 2/2 channel X") for _, what in lines), lines
    phases = [(p, what) for p, what in lines if not what.startswith("step ")]
    assert [what for _, what in phases] == ["analysing", "writing report", "done"], lines
    # 100 % is the end, not the analysis
    assert phases[0][0] < 100 and [p for p, _ in lines].index(100) == len(lines) - 1, lines
