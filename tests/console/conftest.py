"""Helpers for the console tests: the real console against the loopback sim rig."""

from __future__ import annotations

import asyncio
import functools
import time

import pytest
from textual.widgets import Input, Select

WARM = "sim?warm=1&seed=3&watchdog=5"  # mode 3, caged, virtual time
COLD = "sim?seed=3&watchdog=5"  # mode 1, wheels stopped, virtual time


#: A guard against a hang, never a deadline: the sim rig runs in virtual time, and on a busy
#: machine a procedure takes the wall time it takes (a minute idle may be ten on CI).
HANG_GUARD_S = 900.0


async def wait_for(pilot, predicate, what: str = "condition") -> None:
    """Let the app run until ``predicate()`` holds (the rig works on its own thread), then let
    the screen catch up. The poll only yields to the event loop: ``pilot.pause`` queues a
    callback on every widget and redraws the whole screen, and at 20 polls a second that took
    more of the CPU than the simulated rig the test waits on."""
    t_end = time.monotonic() + HANG_GUARD_S
    waited = False
    while not predicate():
        if time.monotonic() > t_end:
            raise AssertionError(f"nothing after {HANG_GUARD_S:g} s waiting for {what}: hung?")
        await asyncio.sleep(0.05)
        waited = True
    if waited:
        await pilot.pause()


async def rig_ready(pilot) -> None:
    app = pilot.app
    await wait_for(
        pilot,
        lambda: (
            app.worker_.state.get().relay is not None
            and app.limits is not None
            and bool(app.catalogue)
        ),
        what="the rig to open and the procedures to load",
    )
    await pilot.pause(0.1)


async def start_procedure(pilot, name: str, params: str = "") -> None:
    """On Procedures (F5), choose ``name``, type ``params`` (``name=value ...`` or ``--resume
    FILE``) and run it (F7)."""
    app = pilot.app
    await pilot.press("f5")
    app.query_one("#proc-name", Select).value = name
    app.query_one("#proc-params", Input).value = params
    await pilot.press("f7")


def nodes_safe(emulator, timeout_s: float = 5.0) -> bool:
    """The emulated nodes' own registers (not the host's view): mode 1, outputs zero, caging released."""
    nodes = emulator.nodes.nodes
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        if (
            nodes["relay"].mode == 1
            and not any(nodes["torquer"].values.values())
            and not any(nodes["command"].values.values())
            and not any(nodes["caging"].inhibit.values())
        ):
            return True
        time.sleep(0.05)
    return False


def outcome(app, what: str):
    """The newest outcome of a command named ``what`` (None if none yet)."""
    for o in reversed(app.outcomes):
        if o.what == what:
            return o
    return None


@pytest.fixture
def out_dir(tmp_path):
    return tmp_path / "out"


def run_async(fn):
    """Run an async test with asyncio (no async plugin is installed; Textual's Pilot is asyncio)."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        return asyncio.run(fn(*args, **kwargs))

    return wrapper
