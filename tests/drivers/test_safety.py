"""``drivers.safety``: the one piece of code that drives the rig safe on an abort, on the
loopback rig (the nodes' own registers are read, not the host's view)."""

from __future__ import annotations

import pytest

from drivers.rig import open_rig
from drivers.safety import SafeOnAbort, describe

pytestmark = pytest.mark.slow


def _outputs(rig) -> tuple[int, bool, bool]:
    """Mode, any torquer bias set, any caging inhibited: from the emulated nodes' registers."""
    nodes = rig.emulator.nodes.nodes
    return (
        nodes["relay"].mode,
        any(nodes["torquer"].values.values()),
        any(nodes["caging"].inhibit.values()),
    )


def test_an_exception_drives_the_rig_safe_reads_it_back_and_goes_on(go_safe_calls):
    with open_rig("sim?warm=1&seed=2") as rig:
        rig.set_caging_inhibit("X", True)
        rig.set_torquer_bias_V("X", 0.4)
        guard = SafeOnAbort(rig, "a test run")
        with pytest.raises(RuntimeError, match="boom"), guard:
            raise RuntimeError("boom")
        assert _outputs(rig) == (1, False, False) and rig.is_safe()
        assert guard.report is not None and guard.report.ok
        assert go_safe_calls == ["a test run aborted (RuntimeError: boom)"]


def test_a_clean_exit_leaves_the_rig_as_it_was(go_safe_calls):
    with open_rig("sim?warm=1&seed=2") as rig:
        with SafeOnAbort(rig, "a test run"):
            rig.set_torquer_bias_V("X", 0.2)
        assert rig.relays.status().mode == 3 and rig.torquers.bias_V("X") == pytest.approx(
            0.2, abs=1e-3
        )
        assert go_safe_calls == []


def test_entered_twice_each_exception_is_handled_once_and_a_new_one_again(go_safe_calls):
    with open_rig("sim?warm=1&seed=2") as rig:
        guard = SafeOnAbort(rig, "run")
        with pytest.raises(KeyboardInterrupt), guard, guard:
            raise KeyboardInterrupt
        assert go_safe_calls == ["run aborted (interrupted)"]
        with pytest.raises(OSError), guard:  # what only the outer entry sees: closing failed
            with guard:
                pass
            raise OSError(28, "No space left on device")
        assert len(go_safe_calls) == 2 and "No space left" in go_safe_calls[1]


def test_describe():
    assert describe(KeyboardInterrupt()) == "interrupted"
    assert describe(ValueError("bad")) == "ValueError: bad"
    assert describe(RuntimeError()) == "RuntimeError"
