"""The CAN protocol of the rig's nodes (relay driver, caging switches, DACs, table).

Full specification: ``docs/protocol.md`` section 2. Classic CAN, 11-bit identifiers, one
node id per device (``NODES``), little-endian payloads:

=================  ==========================  ===========================================
identifier         direction                   payload
=================  ==========================  ===========================================
0x200 + node       host -> node request        seq u8, op u8, index u8, 0, value i32
0x280 + node       node -> host response       seq u8, op u8, index u8, status u8, value i32
0x700 + node       node heartbeat (100 ms)     state u8, flags u8, counter u8
0x700              host heartbeat (100 ms)     state u8 (5), 0, counter u8
0x080 + node       node error (emergency)      code u16, op u8, index u8, detail i32
=================  ==========================  ===========================================

Every request is answered once, with the node's read-back of the affected value. Nothing
here does I/O; ``decode`` turns any identifier and payload into a message or a ProtocolError.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from drivers.errors import ProtocolError

# Node ids and what each one is.
NODES = {"relay": 1, "caging": 2, "torquer": 3, "command": 4, "table": 5}
NODE_NAMES = {v: k for k, v in NODES.items()}
#: Node type codes returned by IDENT (the high byte of the value; the low bytes are the firmware version).
NODE_TYPES = {"relay": 0x11, "caging": 0x12, "torquer": 0x13, "command": 0x14, "table": 0x15}

REQUEST_BASE, RESPONSE_BASE, HEARTBEAT_BASE, EMCY_BASE = 0x200, 0x280, 0x700, 0x080
HOST_HEARTBEAT_ID = HEARTBEAT_BASE

# Opcodes.
OP_GET, OP_SET, OP_IDENT, OP_SAFE, OP_CLEAR = 0x01, 0x02, 0x03, 0x04, 0x05
OP_HOLD, OP_SELECT, OP_RELEASE, OP_STATUS = 0x10, 0x11, 0x12, 0x13
#: relay node: value 1 clamps the platform to the table and opens the motor drive, 0 releases (Ch. V B)
OP_CLAMP = 0x14
OPS = {OP_GET: "GET", OP_SET: "SET", OP_IDENT: "IDENT", OP_SAFE: "SAFE", OP_CLEAR: "CLEAR",
       OP_HOLD: "HOLD", OP_SELECT: "SELECT", OP_RELEASE: "RELEASE", OP_STATUS: "STATUS", OP_CLAMP: "CLAMP"}

# Response status codes.
ST_OK, ST_RANGE, ST_INTERLOCK, ST_BAD_INDEX, ST_BAD_OP, ST_LATCHED, ST_NOT_HELD = range(7)
STATUS_TEXT = {ST_OK: "ok", ST_RANGE: "value out of range", ST_INTERLOCK: "interlock",
               ST_BAD_INDEX: "no such index", ST_BAD_OP: "unknown operation",
               ST_LATCHED: "latched safe (send CLEAR)", ST_NOT_HELD: "mode switches not held"}

# Heartbeat states (as CANopen's NMT states).
HB_BOOT, HB_SAFE, HB_OPERATIONAL = 0x00, 0x04, 0x05
HB_FLAG_ALARM = 0x01

# Emergency codes (CANopen's where one fits).
EMCY_HEARTBEAT_LOST = 0x8130   # the host's heartbeat stopped: the node went safe by itself
EMCY_HARDWARE = 0x5000
EMCY_OVERCURRENT = 0x2310
EMCY_OVERTEMP = 0x4210
EMCY_TEXT = {EMCY_HEARTBEAT_LOST: "host heartbeat lost, node went safe",
             EMCY_HARDWARE: "hardware fault", EMCY_OVERCURRENT: "output over-current",
             EMCY_OVERTEMP: "over-temperature"}

# Relay driver STATUS word bits.
ST_MODE_SHIFT, ST_SELECT_SHIFT = 0, 3
ST_HELD, ST_ALARM = 1 << 6, 1 << 7
ST_AT_SPEED_SHIFT, ST_CAGED_SHIFT, ST_SPIN_SHIFT = 8, 12, 16
#: the platform is clamped and its motor drive open (bits 16-23 are the spin percentage)
ST_CLAMPED = 1 << 24
#: Interlock reason bits in the value of an INTERLOCK response to RELEASE or CLAMP.
WHY_NOT_AT_SPEED, WHY_NOT_CAGED = 0x1, 0x2
#: RELEASE of mode 4, 5 or 6 while clamped; CLAMP outside modes 1-3; CLAMP or unclamp with a
#: command input (V_Td or gamma_c) not at zero
WHY_CLAMPED, WHY_MODE, WHY_COMMAND = 0x4, 0x8, 0x10
#: Modes the platform may be clamped in (the loops do not need it to move)
CLAMP_MODES = (1, 2, 3)

#: DAC set-points travel in microvolts; table angles in micro-degrees.
MICRO = 1e6

_PAYLOAD = struct.Struct("<BBBBi")
_HEARTBEAT = struct.Struct("<BBB")
_EMCY = struct.Struct("<HBBi")


@dataclass(frozen=True)
class Request:
    node: int
    seq: int
    op: int
    index: int
    value: int


@dataclass(frozen=True)
class Response:
    node: int
    seq: int
    op: int
    index: int
    status: int
    value: int


@dataclass(frozen=True)
class Heartbeat:
    node: int          # 0 = the host
    state: int
    flags: int
    counter: int


@dataclass(frozen=True)
class Emergency:
    node: int
    code: int
    op: int
    index: int
    detail: int

    def text(self) -> str:
        return EMCY_TEXT.get(self.code, f"error code 0x{self.code:04x}")


def encode_request(r: Request) -> tuple[int, bytes]:
    return REQUEST_BASE + r.node, _PAYLOAD.pack(r.seq & 0xFF, r.op, r.index, 0, r.value)


def encode_response(r: Response) -> tuple[int, bytes]:
    return RESPONSE_BASE + r.node, _PAYLOAD.pack(r.seq & 0xFF, r.op, r.index, r.status, r.value)


def encode_heartbeat(h: Heartbeat) -> tuple[int, bytes]:
    return HEARTBEAT_BASE + h.node, _HEARTBEAT.pack(h.state, h.flags, h.counter & 0xFF)


def encode_emergency(e: Emergency) -> tuple[int, bytes]:
    return EMCY_BASE + e.node, _EMCY.pack(e.code, e.op, e.index, e.detail)


def _node_of(arbitration_id: int, base: int) -> int:
    node = arbitration_id - base
    if node not in NODE_NAMES:
        raise ProtocolError(f"CAN id 0x{arbitration_id:03x}: node {node} is not a rig node")
    return node


def decode(arbitration_id: int, data: bytes | bytearray, extended: bool = False) -> Request | Response | Heartbeat | Emergency:
    """Any CAN frame -> one of the rig's messages, or ProtocolError naming what is wrong."""
    data = bytes(data)
    if extended or not 0 <= arbitration_id <= 0x7FF:
        raise ProtocolError(f"CAN id 0x{arbitration_id:x}: the rig uses 11-bit identifiers only")
    if len(data) > 8:
        raise ProtocolError(f"CAN id 0x{arbitration_id:03x}: {len(data)} data bytes (classic CAN carries 8)")
    if arbitration_id == HOST_HEARTBEAT_ID or 0x700 < arbitration_id <= 0x77F:
        if len(data) != _HEARTBEAT.size:
            raise ProtocolError(f"heartbeat 0x{arbitration_id:03x}: bad length {len(data)} (expected 3)")
        node = 0 if arbitration_id == HOST_HEARTBEAT_ID else _node_of(arbitration_id, HEARTBEAT_BASE)
        state, flags, counter = _HEARTBEAT.unpack(data)
        if state not in (HB_BOOT, HB_SAFE, HB_OPERATIONAL):
            raise ProtocolError(f"heartbeat 0x{arbitration_id:03x}: unknown state 0x{state:02x}")
        return Heartbeat(node, state, flags, counter)
    for base, kind in ((REQUEST_BASE, Request), (RESPONSE_BASE, Response)):
        if base < arbitration_id < base + 0x80:
            node = _node_of(arbitration_id, base)
            if len(data) != _PAYLOAD.size:
                raise ProtocolError(f"{kind.__name__.lower()} 0x{arbitration_id:03x}: bad length {len(data)} "
                                    f"(expected 8)")
            seq, op, index, status, value = _PAYLOAD.unpack(data)
            if op not in OPS:
                raise ProtocolError(f"{kind.__name__.lower()} 0x{arbitration_id:03x}: unknown opcode 0x{op:02x}")
            if kind is Request:
                return Request(node, seq, op, index, value)
            if status not in STATUS_TEXT:
                raise ProtocolError(f"response 0x{arbitration_id:03x}: unknown status {status}")
            return Response(node, seq, op, index, status, value)
    if EMCY_BASE < arbitration_id < EMCY_BASE + 0x80:
        node = _node_of(arbitration_id, EMCY_BASE)
        if len(data) != _EMCY.size:
            raise ProtocolError(f"emergency 0x{arbitration_id:03x}: bad length {len(data)} (expected 8)")
        code, op, index, detail = _EMCY.unpack(data)
        return Emergency(node, code, op, index, detail)
    raise ProtocolError(f"CAN id 0x{arbitration_id:03x} is not part of the rig's protocol")


def to_micro(value: float) -> int:
    return int(round(value * MICRO))


def from_micro(value: int) -> float:
    return value / MICRO
