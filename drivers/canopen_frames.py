"""CiA 301 frames the host's CAN link reads itself: heartbeat / boot-up and EMCY.

The rest of CANopen (SDO, NMT, PDO) is the ``canopen`` package's. The plan and the object
dictionaries are in ``docs/canopen-plan.md``. The EDS file of each node is
``drivers/eds/<node>.eds``.
"""

from __future__ import annotations

import functools
import struct
from dataclasses import dataclass
from pathlib import Path

import canopen

from drivers.errors import ProtocolError

#: the host's own CANopen node id: its heartbeat goes out on 0x700 + 0x7F
HOST_NODE_ID = 0x7F
HOST_HEARTBEAT_COB = 0x700 + HOST_NODE_ID

NMT_BOOT, NMT_STOPPED, NMT_OPERATIONAL, NMT_PRE_OPERATIONAL = 0x00, 0x04, 0x05, 0x7F
NMT_STATE_TEXT = {
    NMT_BOOT: "boot-up",
    NMT_STOPPED: "stopped",
    NMT_OPERATIONAL: "operational",
    NMT_PRE_OPERATIONAL: "pre-operational",
}
NMT_START = 0x01
NMT_ENTER_PRE_OPERATIONAL = 0x80  # CiA 301: a stopped node answers SDO again

#: CiA 301 emergency codes the rig's nodes send
EMCY_ERROR_RESET = 0x0000
EMCY_HEARTBEAT = 0x8130  # the host's heartbeat stopped: outputs at their error values
EMCY_HARDWARE, EMCY_OVERCURRENT, EMCY_OVERTEMP = 0x5000, 0x2310, 0x4210
EMCY_TEXT = {
    EMCY_HEARTBEAT: "host heartbeat lost, outputs at their error values",
    EMCY_HARDWARE: "hardware fault",
    EMCY_OVERCURRENT: "output over-current",
    EMCY_OVERTEMP: "over-temperature",
}

#: CiA 303-2 SI unit code of the volt, as in 0x6450
SI_VOLT = 0x00260000
#: CiA 401 device types (0x1000): analogue outputs, digital outputs
DEVICE_TYPE_401_AO = 0x00080191
DEVICE_TYPE_401_DO = 0x00020191

EDS_DIR = Path(__file__).with_name("eds")

_EMCY = struct.Struct("<HB5s")


def eds_path(node: str) -> Path:
    """The EDS file of the rig node ``node`` (its object dictionary): a core node's is in
    ``drivers/eds``, a device's beside its module (``drivers.devices``)."""
    core = EDS_DIR / f"{node}.eds"
    if core.is_file():
        return core
    from drivers.devices import catalogue  # its modules import this one

    device = catalogue().get(node)
    return device.eds if device is not None else core


def object_dictionary(node: str, node_id: int) -> canopen.ObjectDictionary:
    """The object dictionary of rig node ``node`` from its EDS (``eds_path``), parsed once for
    each version of the file (path, mtime, size) and shared: parsing is configparser work, and
    every rig opened needs ten (a host and a simulated side for each node), a third of opening
    the simulated rig. The dictionary is the EDS's description and is only read (a node's
    values live in its SDO server's data store or in the device); a copy for each caller cost
    a fifth of opening the rig again."""
    path = eds_path(node)
    st = path.stat()
    return _parsed_eds(str(path), st.st_mtime_ns, st.st_size, node_id)


@functools.lru_cache(maxsize=64)
def _parsed_eds(path: str, mtime_ns: int, size: int, node_id: int) -> canopen.ObjectDictionary:
    return canopen.import_od(path, node_id)


@dataclass(frozen=True)
class CoHeartbeat:
    node: int
    state: int

    def text(self) -> str:
        return NMT_STATE_TEXT.get(self.state, f"state 0x{self.state:02x}")


@dataclass(frozen=True)
class CoEmergency:
    node: int
    code: int
    register: int
    data: bytes

    def text(self) -> str:
        return EMCY_TEXT.get(self.code, f"error code 0x{self.code:04x}")


def node_of(cob_id: int) -> int:
    """The node id in a predefined-connection-set COB-ID (0 for NMT and SYNC)."""
    return cob_id & 0x7F


def decode_heartbeat(cob_id: int, data: bytes | bytearray) -> CoHeartbeat:
    if len(data) != 1:
        raise ProtocolError(
            f"CANopen heartbeat 0x{cob_id:03x}: {len(data)} data bytes (expected 1)"
        )
    state = data[0] & 0x7F  # bit 7 is the node-guarding toggle
    if state not in NMT_STATE_TEXT:
        raise ProtocolError(f"CANopen heartbeat 0x{cob_id:03x}: unknown NMT state 0x{state:02x}")
    return CoHeartbeat(node_of(cob_id), state)


def decode_emergency(cob_id: int, data: bytes | bytearray) -> CoEmergency:
    if len(data) != 8:
        raise ProtocolError(f"CANopen EMCY 0x{cob_id:03x}: {len(data)} data bytes (expected 8)")
    code, register, rest = _EMCY.unpack(bytes(data))
    return CoEmergency(node_of(cob_id), code, register, rest)
