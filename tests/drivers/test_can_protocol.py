"""The rig's CAN protocol: every message round-trips, and any frame is a message or a ProtocolError.

``decode(arbitration_id, data, extended)`` is the only way bytes from the bus become rig
messages, so hypothesis throws arbitrary identifiers and payloads at it: the answer is one of
the four message types (which re-encodes to the very same identifier and payload) or a
:class:`ProtocolError` whose message names what is wrong, never another exception.
"""

from __future__ import annotations

import re

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from drivers import can_protocol as cp
from drivers.can_protocol import Emergency, Heartbeat, Request, Response, decode
from drivers.errors import ProtocolError

FUZZ = settings(max_examples=400, deadline=500)
FAST = settings(max_examples=150, deadline=500)

node_ids = st.sampled_from(sorted(cp.NODES.values()))
u8 = st.integers(0, 255)
u16 = st.integers(0, 0xFFFF)
i32 = st.integers(-(2**31), 2**31 - 1)
ops = st.sampled_from(sorted(cp.OPS))
statuses = st.sampled_from(sorted(cp.STATUS_TEXT))
hb_states = st.sampled_from([cp.HB_BOOT, cp.HB_SAFE, cp.HB_OPERATIONAL])

requests = st.builds(Request, node_ids, u8, ops, u8, i32)
responses = st.builds(Response, node_ids, u8, ops, u8, statuses, i32)
heartbeats = st.builds(Heartbeat, st.just(0) | node_ids, hb_states, u8, u8)
emergencies = st.builds(Emergency, node_ids, u16, u8, u8, i32)

ENCODERS = {Request: cp.encode_request, Response: cp.encode_response, Heartbeat: cp.encode_heartbeat,
            Emergency: cp.encode_emergency}


def _encode(msg):
    return ENCODERS[type(msg)](msg)


def _outcome(*args):
    try:
        return decode(*args)
    except ProtocolError as exc:
        return exc


#: Every identifier the rig uses, and the message type it carries.
VALID_IDS = {cp.HOST_HEARTBEAT_ID: Heartbeat}
for _n in cp.NODES.values():
    VALID_IDS.update({cp.REQUEST_BASE + _n: Request, cp.RESPONSE_BASE + _n: Response,
                      cp.HEARTBEAT_BASE + _n: Heartbeat, cp.EMCY_BASE + _n: Emergency})
GOOD_PAYLOAD = {Request: bytes([7, cp.OP_GET, 0, 0]) + (5).to_bytes(4, "little", signed=True),
                Response: bytes([7, cp.OP_GET, 0, cp.ST_OK]) + (5).to_bytes(4, "little", signed=True),
                Heartbeat: bytes([cp.HB_OPERATIONAL, 0, 9]),
                Emergency: (0x8130).to_bytes(2, "little") + bytes([1, 2]) + (-1).to_bytes(4, "little", signed=True)}


# --------------------------------------------------------------------------- round trips
@FAST
@given(st.one_of(requests, responses, heartbeats, emergencies))
@example(Request(1, 0, cp.OP_SET, 255, -(2**31)))
@example(Response(5, 255, cp.OP_STATUS, 0, cp.ST_NOT_HELD, 2**31 - 1))
@example(Heartbeat(0, cp.HB_OPERATIONAL, 0, 255))
@example(Emergency(3, 0xFFFF, 0, 0, -1))
def test_every_message_round_trips_through_decode(msg):
    """encode_* -> decode gives back the same message (seq 0..255, int32 values, every rig node)."""
    can_id, data = _encode(msg)
    assert 0 <= can_id <= 0x7FF
    assert len(data) == (3 if isinstance(msg, Heartbeat) else 8)
    assert decode(can_id, data) == msg
    assert decode(can_id, bytearray(data), False) == msg


def test_wire_layout_matches_the_specification():
    """Identifiers and little-endian payloads exactly as in the module's table."""
    assert cp.encode_request(Request(3, 0x12, cp.OP_SET, 2, -2)) == (0x203, b"\x12\x02\x02\x00\xfe\xff\xff\xff")
    assert cp.encode_response(Response(4, 1, cp.OP_GET, 0, cp.ST_RANGE, 0x01020304)) == (
        0x284, b"\x01\x01\x00\x01\x04\x03\x02\x01")
    assert cp.encode_heartbeat(Heartbeat(2, cp.HB_SAFE, cp.HB_FLAG_ALARM, 300)) == (0x702, b"\x04\x01\x2c")
    assert cp.encode_heartbeat(Heartbeat(0, cp.HB_OPERATIONAL, 0, 1)) == (0x700, b"\x05\x00\x01")
    assert cp.encode_emergency(Emergency(5, cp.EMCY_OVERTEMP, cp.OP_HOLD, 1, 7)) == (
        0x085, b"\x10\x42\x10\x01\x07\x00\x00\x00")


def test_every_11_bit_identifier_is_classified_exactly():
    """Of all 2048 identifiers, exactly the rig's own decode (to the right type and node); the rest raise."""
    accepted = {}
    for can_id in range(0x800):
        for kind in (Request, Heartbeat):  # an 8-byte payload that is valid for all 8-byte kinds, and a 3-byte one
            got = _outcome(can_id, GOOD_PAYLOAD[kind])
            if not isinstance(got, ProtocolError):
                accepted[can_id] = type(got)
    assert accepted == VALID_IDS
    for can_id, kind in VALID_IDS.items():
        msg = decode(can_id, GOOD_PAYLOAD[kind])
        assert _encode(msg) == (can_id, GOOD_PAYLOAD[kind])
        assert msg.node == (0 if can_id == cp.HOST_HEARTBEAT_ID else can_id & 0x7F)


# --------------------------------------------------------------------------- fuzz
ids = st.one_of(st.integers(0, 0x7FF), st.sampled_from(sorted(VALID_IDS)),
                st.integers(-(2**40), 2**40), st.sampled_from([-1, 0x800, 0x1FFFFFFF, 2**64]))
payloads = st.one_of(st.binary(max_size=16),
                     st.sampled_from(list(GOOD_PAYLOAD.values())),
                     st.tuples(u8, ops, u8, statuses, i32).map(
                         lambda t: bytes(t[:4]) + t[4].to_bytes(4, "little", signed=True)))


@FUZZ
@given(ids, payloads, st.booleans())
@example(0x203, GOOD_PAYLOAD[Request], False)
@example(0x703, GOOD_PAYLOAD[Heartbeat], False)
def test_any_can_frame_decodes_to_a_message_or_a_protocol_error(can_id, data, extended):
    """Any id, payload and id format: a message that re-encodes to the same frame, or ProtocolError.

    The one byte a message does not keep is a request's reserved fourth byte (written as 0).
    """
    got = _outcome(can_id, data, extended)
    if isinstance(got, ProtocolError):
        assert str(got)
        return
    assert isinstance(got, (Request, Response, Heartbeat, Emergency))
    assert not extended and 0 <= can_id <= 0x7FF
    assert VALID_IDS[can_id] is type(got)
    want = bytes(data)
    if isinstance(got, Request):
        want = want[:3] + b"\x00" + want[4:]
    assert _encode(got) == (can_id, want)


# --------------------------------------------------------------------------- errors
@pytest.mark.parametrize("kind", [Request, Response, Heartbeat, Emergency])
def test_wrong_payload_lengths_raise(kind):
    """Every length but the right one (0..16 bytes) is refused, naming the length."""
    can_id = next(i for i, k in VALID_IDS.items() if k is kind and i != cp.HOST_HEARTBEAT_ID)
    good = GOOD_PAYLOAD[kind]
    for n in range(17):
        if n == len(good):
            assert isinstance(decode(can_id, good), kind)
            continue
        data = (good * 6)[:n]
        problem = f"{n} data bytes (classic CAN carries 8)" if n > 8 else f"bad length {n} (expected {len(good)})"
        with pytest.raises(ProtocolError, match=re.escape(problem)):
            decode(can_id, data)
    with pytest.raises(ProtocolError, match=re.escape("heartbeat 0x700: bad length 8 (expected 3)")):
        decode(cp.HOST_HEARTBEAT_ID, GOOD_PAYLOAD[Request])


@pytest.mark.parametrize("base, kind", [(cp.REQUEST_BASE, "request"), (cp.RESPONSE_BASE, "response")])
def test_unknown_opcodes_raise(base, kind):
    """All 256 - 10 opcodes that are not in OPS (CLAMP the tenth) are refused, in requests and in responses."""
    bad = [op for op in range(256) if op not in cp.OPS]
    assert len(bad) == 256 - 10
    for op in bad:
        data = bytes([1, op, 0, 0, 0, 0, 0, 0])
        with pytest.raises(ProtocolError, match=re.escape(f"{kind} 0x{base + 1:03x}: unknown opcode 0x{op:02x}")):
            decode(base + 1, data)


def test_unknown_response_status_and_heartbeat_state_raise():
    """Status codes beyond ST_NOT_HELD and heartbeat states other than boot/safe/operational are refused."""
    for status in range(len(cp.STATUS_TEXT), 256):
        with pytest.raises(ProtocolError, match=f"unknown status {status}$"):
            decode(0x281, bytes([0, cp.OP_GET, 0, status, 0, 0, 0, 0]))
    for state in set(range(256)) - {cp.HB_BOOT, cp.HB_SAFE, cp.HB_OPERATIONAL}:
        with pytest.raises(ProtocolError, match=f"unknown state 0x{state:02x}"):
            decode(0x701, bytes([state, 0, 0]))


@pytest.mark.parametrize("base", [cp.REQUEST_BASE, cp.RESPONSE_BASE, cp.HEARTBEAT_BASE, cp.EMCY_BASE])
def test_unknown_node_ids_raise(base):
    """Node numbers 6..127 in every message range are not rig nodes, and the message says so."""
    kind = VALID_IDS[base + 1]
    for node in range(max(cp.NODES.values()) + 1, 0x80):
        with pytest.raises(ProtocolError, match=re.escape(f"node {node} is not a rig node")):
            decode(base + node, GOOD_PAYLOAD[kind])


@pytest.mark.parametrize("can_id", [0x000, 0x001, 0x07F, 0x080, 0x100, 0x200, 0x280, 0x300, 0x6FF, 0x780, 0x7FF])
def test_identifiers_outside_the_protocol_raise(can_id):
    """Base identifiers without a node, and ids in no range, are not part of the protocol."""
    for data in (GOOD_PAYLOAD[Request], GOOD_PAYLOAD[Heartbeat]):
        with pytest.raises(ProtocolError, match=re.escape(f"CAN id 0x{can_id:03x} is not part of the rig's protocol")):
            decode(can_id, data)


@FAST
@given(st.one_of(st.integers(0x800, 2**40), st.integers(-(2**40), -1)), st.binary(max_size=8))
@example(0x800, GOOD_PAYLOAD[Request])
@example(0x1FFFFFFF, GOOD_PAYLOAD[Request])
@example(0x10000203, GOOD_PAYLOAD[Request])  # 0x203 with high bits set: not an alias of node 3
def test_identifiers_beyond_11_bits_raise(can_id, data):
    """Ids above 0x7FF (or negative) never alias a rig id."""
    with pytest.raises(ProtocolError, match="11-bit identifiers only"):
        decode(can_id, data)


@pytest.mark.parametrize("can_id, kind", sorted(VALID_IDS.items()))
def test_extended_frames_raise_even_with_a_rig_identifier(can_id, kind):
    """A 29-bit frame is refused although its id and payload would be valid in 11-bit format."""
    assert isinstance(decode(can_id, GOOD_PAYLOAD[kind], False), kind)
    with pytest.raises(ProtocolError, match=re.escape(f"CAN id 0x{can_id:x}: the rig uses 11-bit identifiers only")):
        decode(can_id, GOOD_PAYLOAD[kind], True)


def test_emergency_text_names_known_codes():
    """Known emergency codes read as text; unknown ones as hex."""
    assert Emergency(1, cp.EMCY_HEARTBEAT_LOST, 0, 0, 0).text() == "host heartbeat lost, node went safe"
    assert Emergency(1, 0x1234, 0, 0, 0).text() == "error code 0x1234"
