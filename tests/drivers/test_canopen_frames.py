"""The CiA 301 frames the host reads itself (heartbeat, EMCY) and what ``CanLink`` makes of any
frame on the bus: property tests over every identifier and payload (issue 21, acceptance B).

The link is a real ``CanLink`` on a python-can virtual bus; frames are handed to its receive
handler as its notifier would hand them, so no timing is involved.
"""

from __future__ import annotations

import struct
import uuid

import can
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers import canopen_frames as cf
from drivers import rig_nodes as rn
from drivers.can_link import CanLink
from drivers.errors import DeviceTimeout, NodeError, NodeReset, ProtocolError

OURS = ("relay", "torquer")  # the link below uses these two
OUR_IDS = [rn.NODES[n] for n in OURS]
ids = st.integers(0, 0x7FF)
payloads = st.binary(max_size=8)


@given(ids, payloads)
def test_any_heartbeat_frame_decodes_or_is_a_protocol_error(cob_id, data):
    try:
        m = cf.decode_heartbeat(cob_id, data)
    except ProtocolError as exc:
        assert f"0x{cob_id:03x}" in str(exc)
        return
    assert len(data) == 1 and m.state == data[0] & 0x7F and m.node == cob_id & 0x7F
    assert m.text() == cf.NMT_STATE_TEXT[m.state]


@given(ids, payloads)
def test_any_emcy_frame_decodes_or_is_a_protocol_error(cob_id, data):
    try:
        m = cf.decode_emergency(cob_id, data)
    except ProtocolError as exc:
        assert f"0x{cob_id:03x}" in str(exc) and "expected 8" in str(exc)
        return
    assert len(data) == 8
    assert struct.pack("<HB5s", m.code, m.register, m.data) == data


def test_known_emcy_codes_are_named():
    assert cf.CoEmergency(3, cf.EMCY_OVERTEMP, 0x11, bytes(5)).text() == "over-temperature"
    assert cf.CoEmergency(3, 0x1234, 0, bytes(5)).text() == "error code 0x1234"


@pytest.fixture(scope="module")
def link():
    bus = can.Bus(
        interface="virtual", channel=f"frames-{uuid.uuid4().hex[:8]}", receive_own_messages=False
    )
    # no node answers here: a silence limit beyond the test's length keeps the watch quiet
    lk = CanLink(bus, list(OURS), node_timeout_s=1e6, heartbeat_period_s=3600.0, channel="test")
    for name in OURS:
        lk.started(name)  # connected: from here an EMCY is this session's fault
    yield lk
    lk.close()


def feed(link: CanLink, cob_id: int, data: bytes, extended: bool = False):
    """The frame through the link's receive handler; the fault it latched (cleared after)."""
    link._on_message(can.Message(arbitration_id=cob_id, data=data, is_extended_id=extended))
    fault = link.faults.clear()  # the next example starts unlatched ...
    link._operational.clear()  # ... and with no node up yet
    return fault


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(ids.filter(lambda i: i & 0x7F not in OUR_IDS), payloads, st.booleans())
def test_frames_of_node_ids_the_rig_does_not_use_never_latch(link, cob_id, data, extended):
    """Another module's boot-up, heartbeat, PDO, SDO, EMCY of any length; NMT and SYNC."""
    assert feed(link, cob_id, data, extended) is None


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.sampled_from(OUR_IDS), st.integers(0, 0xF).map(lambda f: f << 7), payloads)
def test_a_frame_of_our_nodes_latches_only_what_is_malformed_or_alarming(
    link, node, function, data
):
    cob_id = function | node
    fault = feed(link, cob_id, data)
    if function == 0x700:  # heartbeat: one byte, a known NMT state; a first boot-up is no fault
        ok = len(data) == 1 and data[0] & 0x7F in cf.NMT_STATE_TEXT
        assert (fault is None) if ok else isinstance(fault, ProtocolError)
    elif function == 0x080:  # EMCY: 8 bytes; any code but 0 (error reset) is a node error
        if len(data) != 8:
            assert isinstance(fault, ProtocolError)
        elif struct.unpack_from("<H", data)[0] == cf.EMCY_ERROR_RESET:
            assert fault is None
        else:
            assert isinstance(fault, NodeError) and fault.node == rn.NODE_NAMES[node]
    elif function == 0x580:  # an SDO answer: 8 bytes, or the link cannot trust the node
        assert (fault is None) if len(data) == 8 else isinstance(fault, ProtocolError)
    else:  # PDOs, the SDO requests of another client: not alarming
        assert fault is None


def test_an_operational_node_that_boots_or_leaves_operational_latches(link):
    torquer = rn.NODES["torquer"]
    for state, kind in (
        (cf.NMT_BOOT, NodeReset),
        (cf.NMT_PRE_OPERATIONAL, NodeError),
        (cf.NMT_STOPPED, NodeError),
    ):
        link._on_message(
            can.Message(
                arbitration_id=0x700 + torquer,
                data=bytes([cf.NMT_OPERATIONAL]),
                is_extended_id=False,
            )
        )
        fault = feed(link, 0x700 + torquer, bytes([state]))
        assert isinstance(fault, kind) and "'torquer' (id 3)" in str(fault)


def test_a_node_counts_as_up_only_once_its_heartbeat_says_operational(link):
    """The NMT start is not answered: a pre-operational heartbeat the node sent before it saw
    the start may still arrive after it. Until an operational one arrives the node is not up,
    so that frame latches nothing; a node that never gets there is named."""
    torquer = rn.NODES["torquer"]
    link._operational.clear()
    assert feed(link, 0x700 + torquer, bytes([cf.NMT_PRE_OPERATIONAL])) is None
    with pytest.raises(
        DeviceTimeout, match=r"node\(s\) torquer \(id 3\) did not report the operational state"
    ):
        link.wait_operational(["torquer"], 0.05)
    link._on_message(
        can.Message(
            arbitration_id=0x700 + torquer, data=bytes([cf.NMT_OPERATIONAL]), is_extended_id=False
        )
    )
    link.wait_operational(["torquer"], 0.05)
    assert link.faults.fault is None


def test_an_emcy_from_before_the_hosts_nmt_start_is_not_this_sessions_fault():
    """Issue 35 item 7: a node tripped at the previous session's end (its watchdog: the host
    heartbeat stopped) may send its EMCY while this host connects; it sits at its error values
    and the NMT start changes none of them. Once started, the same frame latches."""
    bus = can.Bus(
        interface="virtual", channel=f"stale-{uuid.uuid4().hex[:8]}", receive_own_messages=False
    )
    lk = CanLink(bus, ["torquer"], node_timeout_s=1e6, heartbeat_period_s=3600.0, channel="test")
    try:
        trip = struct.pack("<HB5s", cf.EMCY_HEARTBEAT, 0x11, bytes(5))
        lk._on_message(can.Message(arbitration_id=0x083, data=trip, is_extended_id=False))
        assert lk.faults.fault is None
        lk._on_message(can.Message(arbitration_id=0x083, data=trip[:5], is_extended_id=False))
        assert isinstance(lk.faults.clear(), ProtocolError)  # malformed latches, started or not
        lk.started("torquer")
        lk._on_message(can.Message(arbitration_id=0x083, data=trip, is_extended_id=False))
        assert isinstance(lk.faults.fault, NodeError)
    finally:
        lk.close()
