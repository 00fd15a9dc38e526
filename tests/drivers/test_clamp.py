"""The platform clamp over the wire (relay node, docs/protocol.md): its status bit and its
interlocks, enforced by the node and checked first by the driver, and the safe state that
never moves it."""

from __future__ import annotations

import pytest

from drivers import rig_nodes as rn
from drivers.errors import InterlockError
from drivers.relay import R_CLAMP
from drivers.rig import open_rig


@pytest.fixture
def rig():
    r = open_rig("sim?warm=1")
    yield r
    r.close()


def test_clamp_and_release_read_back_in_the_status_word(rig):
    assert rig.relays.status().clamped is False
    assert rig.clamp() is True
    assert rig.relays.status().clamped is True
    assert rig.relays.node.read(R_CLAMP) == 1
    rig.unclamp()
    assert rig.relays.status().clamped is False


@pytest.mark.parametrize("mode", [4, 5, 6])
def test_gyro_and_external_modes_are_refused_while_clamped(rig, mode):
    rig.clamp()
    with pytest.raises(InterlockError, match="platform clamped.*fbs clamp off"):
        rig.set_mode(mode)
    # the node refuses by itself, whatever the host checked
    rig.relays.hold()
    rig.relays.select(mode)
    with pytest.raises(InterlockError, match="platform clamped") as exc:
        rig.relays.release()
    assert exc.value.detail & rn.WHY_CLAMPED
    assert rig.relays.status().mode == 3


@pytest.mark.parametrize("mode", [4, 5])
def test_clamp_is_refused_in_the_gyro_modes(rig, mode):
    rig.set_mode(mode)
    with pytest.raises(InterlockError, match="modes 1-3"):
        rig.clamp()
    with pytest.raises(InterlockError, match="mode outside 1-3") as exc:
        rig.relays._set_clamp(True)
    assert exc.value.detail & rn.WHY_MODE
    assert rig.relays.status().clamped is False


def test_clamp_and_release_need_the_command_inputs_at_zero(rig):
    rig.set_ac_bias_V("Y", 0.05)
    with pytest.raises(InterlockError, match="command input"):
        rig.clamp()
    rig.set_ac_bias_V("Y", 0.0)
    rig.clamp()
    rig.set_command_torque_V("X", 0.1)
    with pytest.raises(InterlockError, match="command input"):
        rig.unclamp()
    with pytest.raises(InterlockError, match="command input not at zero") as exc:
        rig.relays._set_clamp(False)
    assert exc.value.detail & rn.WHY_COMMAND
    assert rig.relays.status().clamped is True
    rig.set_command_torque_V("X", 0.0)
    rig.unclamp()
    assert rig.relays.status().clamped is False


def test_the_safe_state_never_moves_the_clamp(rig):
    rig.clamp()
    report = rig.safe()
    assert report.ok and rig.is_safe()
    st = rig.relays.status()
    assert st.mode == 1 and st.clamped is True
    rig.set_mode(2)  # modes 1-3 stay allowed while clamped
    rig.unclamp()
    assert rig.relays.status().clamped is False
