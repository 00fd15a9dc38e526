"""The console's mode panel says when the platform is clamped (the open-loop state, Ch. V B)."""

from __future__ import annotations

from console.modes import interlock_words
from drivers.relay import RelayStatus


def _status(clamped: bool) -> RelayStatus:
    return RelayStatus(
        mode=3,
        selected=3,
        held=False,
        alarm=False,
        at_speed=dict.fromkeys(("X", "Y", "Z", "XRD"), True),
        caged=dict.fromkeys(("X", "Y", "Z", "XRD"), True),
        spin_fraction=1.0,
        clamped=clamped,
    )


def test_a_clamped_rig_says_so_and_refuses_the_gyro_modes():
    text = interlock_words(_status(True), None).plain
    assert "platform CLAMPED" in text and "fbs clamp off" in text
    assert "allowed" not in text
    assert "CLAMPED" not in interlock_words(_status(False), None).plain
