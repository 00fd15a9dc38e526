"""A CANopen module written from CiA 301 and CiA 401 alone: raw python-can frames, no canopen
package and none of the project's node code (issue 35 G). It varies what bought modules
legitimately vary: its heartbeat off at power-on (0x1017 = 0, a common factory setting) or at
another period, a late boot-up, the stopped state, slow SDO answers, malformed frames.

Expedited SDO only (every object here fits in 4 bytes); an unknown object is aborted with
0x06020000. NMT: start, stop, enter pre-operational, reset node and reset communication (each
reset: a boot-up frame, then pre-operational).
"""

from __future__ import annotations

import struct
import threading
import time

import can

BOOT, STOPPED, OPERATIONAL, PRE_OPERATIONAL = 0x00, 0x04, 0x05, 0x7F
NMT_STATE = {0x01: OPERATIONAL, 0x02: STOPPED, 0x80: PRE_OPERATIONAL}
#: CiA 401 analogue outputs, 4 channels (the torquer DACs): what the host reads and configures
AO_401_OBJECTS: dict[tuple[int, int], tuple[int, int]] = {
    (0x1000, 0): (0x00080191, 4),
    (0x1001, 0): (0, 1),
    (0x1018, 2): (0x13, 4),
    (0x1016, 1): (0, 4),
    (0x1017, 0): (0, 2),
    (0x1029, 1): (0, 1),
    **{(0x6411, s): (0, 2) for s in range(1, 5)},
    **{(0x6443, s): (0, 1) for s in range(1, 5)},
    **{(0x6444, s): (0, 4) for s in range(1, 5)},
    # RPDO1 as the EDS has it: outputs 1-4 in order, on 0x200 + node id, acting on arrival
    (0x1400, 1): (0x203, 4),
    (0x1400, 2): (255, 1),
    (0x1600, 0): (4, 1),
    **{(0x1600, s): (0x64110010 | (s << 8), 4) for s in range(1, 5)},
}


class RawNode:
    """Node ``node_id`` on python-can channel ``channel`` (virtual), objects (index, sub) ->
    (value, size in bytes)."""

    def __init__(
        self,
        channel: str,
        node_id: int,
        objects: dict[tuple[int, int], tuple[int, int]],
        *,
        boot_delay_s: float = 0.0,
        state: int = PRE_OPERATIONAL,
        sdo_delay_s: float = 0.0,
        short_sdo: bool = False,
        other_object: bool = False,
        mute_sdo: bool = False,
        read_only: set[int] = frozenset(),
    ) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        self.node_id = node_id
        self.objects = {k: list(v) for k, v in objects.items()}
        self.state = BOOT
        self.initial_state = state
        self.sdo_delay_s = sdo_delay_s
        self.short_sdo = short_sdo
        #: download answers name the next object (a confused module); no SDO answers at all
        self.other_object, self.mute_sdo = other_object, mute_sdo
        #: objects (by index) whose writes are aborted 0x06010002 (a module that keeps its own)
        self.read_only = set(read_only)
        self.received: list[can.Message] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._boot_at = time.monotonic() + boot_delay_s
        self._next_hb = float("inf")
        self._thread = threading.Thread(target=self._run, name=f"rawnode-{node_id}", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ frames out
    def send(self, cob_id: int, data: bytes) -> None:
        self.bus.send(can.Message(arbitration_id=cob_id, data=data, is_extended_id=False))

    def emcy(self, code: int, register: int = 0x11, length: int = 8) -> None:
        self.send(0x80 + self.node_id, struct.pack("<HB5s", code, register, bytes(5))[:length])

    def _boot(self, state: int) -> None:
        self.send(0x700 + self.node_id, bytes([BOOT]))
        self.state = state
        self._schedule_heartbeat(time.monotonic())

    def _schedule_heartbeat(self, now: float) -> None:
        period_ms = self.objects[(0x1017, 0)][0]
        self._next_hb = now + period_ms / 1000 if period_ms else float("inf")

    # ------------------------------------------------------------------ the node's loop
    def _run(self) -> None:
        booted = False
        while not self._stop.is_set():
            now = time.monotonic()
            if not booted and now >= self._boot_at:
                booted = True
                self._boot(self.initial_state)
            if booted and now >= self._next_hb:
                self.send(0x700 + self.node_id, bytes([self.state]))
                self._schedule_heartbeat(now)
            msg = self.bus.recv(timeout=0.005)
            if msg is None or not booted:
                continue  # powered off: deaf
            self.received.append(msg)
            if (
                msg.arbitration_id == 0x000
                and len(msg.data) == 2
                and msg.data[1] in (0, self.node_id)
            ):
                self._nmt(msg.data[0])
            elif (
                msg.arbitration_id == 0x600 + self.node_id
                and self.state != STOPPED
                and not self.mute_sdo
            ):
                self._sdo(bytes(msg.data))  # CiA 301: a stopped node serves no SDO
            elif self.state == OPERATIONAL:
                self._rpdo(msg)

    def _nmt(self, command: int) -> None:
        if command in NMT_STATE:
            self.state = NMT_STATE[command]  # not answered: the next heartbeat says it
        elif command in (0x81, 0x82):
            self._boot(PRE_OPERATIONAL)

    def _sdo(self, req: bytes) -> None:
        if len(req) != 8:
            return
        if self.sdo_delay_s:
            time.sleep(self.sdo_delay_s)
        ccs, index, sub = req[0] >> 5, int.from_bytes(req[1:3], "little"), req[3]
        key = (index, sub)
        if key not in self.objects:
            return self._answer(struct.pack("<BHBI", 0x80, index, sub, 0x06020000))
        value, size = self.objects[key]
        if ccs == 2:  # upload: expedited, size given
            n = 4 - size
            self._answer(
                struct.pack("<BHB", 0x43 | (n << 2), index, sub)
                + (value & 0xFFFFFFFF).to_bytes(4, "little")
            )
        elif ccs == 1 and index in self.read_only:
            self._answer(struct.pack("<BHBI", 0x80, index, sub, 0x06010002))
        elif ccs == 1 and req[0] & 0x02:  # expedited download
            n = (req[0] >> 2) & 3 if req[0] & 0x01 else 0
            raw = int.from_bytes(req[4 : 8 - n], "little")
            self.objects[key][0] = raw
            if key == (0x1017, 0):
                self._schedule_heartbeat(time.monotonic())
            self._answer(struct.pack("<BHB4x", 0x60, index + self.other_object, sub))
        else:
            self._answer(struct.pack("<BHBI", 0x80, index, sub, 0x05040001))

    def _rpdo(self, msg: can.Message) -> None:
        """A receive PDO: its mapped objects from the frame, in the order of its own mapping."""
        for n in range(4):
            cob = self.objects.get((0x1400 + n, 1), [0x80000000])[0]
            if cob & 0x80000000 or msg.arbitration_id != cob & 0x7FF:
                continue
            pos = 0
            for s in range(1, self.objects[(0x1600 + n, 0)][0] + 1):
                entry = self.objects[(0x1600 + n, s)][0]
                key, nbytes = (entry >> 16, (entry >> 8) & 0xFF), (entry & 0xFF) // 8
                if key in self.objects:
                    self.objects[key][0] = int.from_bytes(
                        msg.data[pos : pos + nbytes], "little", signed=True
                    )
                pos += nbytes

    def _answer(self, data: bytes) -> None:
        self.send(0x580 + self.node_id, data[:7] if self.short_sdo else data)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.bus.shutdown()
