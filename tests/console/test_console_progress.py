"""Issue 37 item 4, acceptance B (console): a procedure's progress never goes back, neither in
what the rig thread publishes nor in the header and the procedure panel that show it. The old
runner published a finished step twice over at its end and fell back at the next step (the
issue saw the header go 100 -> 61 %); a cold rig's mode 3 step (the wheels spin up) takes rig
time, which is what made it show."""

from __future__ import annotations

import re

import pytest
from textual.widgets import ProgressBar, Static

from console.app import ConsoleApp

from .conftest import COLD, rig_ready, run_async, start_procedure, wait_for

pytestmark = pytest.mark.slow

#: one channel, one repetition, short holds: seconds of wall time in virtual time
SHORT = 'channels=["X"] repetitions=1 min_caged_s=10 hold_s=5 null_s=5 restore_s=10'


@run_async
async def test_a_procedures_progress_never_goes_back_in_the_header_or_the_panel(out_dir):
    app = ConsoleApp(COLD, out_dir=out_dir)
    published = []  # every ProcedureInfo the rig thread sets
    state = app.worker_.state
    update = state.update

    def recording_update(**changes):
        snap = update(**changes)
        if changes.get("procedure") is not None:
            published.append(changes["procedure"])
        return snap

    state.update = recording_update
    header, bar = [], []

    def sample() -> bool:
        """What the operator sees, as the test runs (every few refreshes)."""
        m = re.search(r" stopwatch (\d+) % ", str(app.query_one("#status", Static).render()))
        if m:
            header.append(int(m[1]))
        bar.append(app.query_one("#proc-bar", ProgressBar).progress)
        return app.last_summary is not None

    async with app.run_test(size=(160, 30)) as pilot:
        await rig_ready(pilot)
        await start_procedure(pilot, "stopwatch", SHORT)
        await wait_for(pilot, sample, what="the procedure to end")
        assert app.last_summary.status == "complete", app.last_summary.error
    fractions = [p.fraction for p in published]
    assert all(b >= a for a, b in zip(fractions, fractions[1:])), fractions
    phases = [p.phase for p in published]
    assert phases[-3:] == ["analysing", "writing report", "done"] and fractions[-1] == 1.0, phases
    assert len(header) > 3 and all(b >= a for a, b in zip(header, header[1:])), header
    assert all(b >= a for a, b in zip(bar, bar[1:])), bar
