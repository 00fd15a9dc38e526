"""The host's end of the CAN bus: requests with acknowledgement, heartbeats both ways.

``CanLink`` owns a python-can bus. It sends the host heartbeat, watches every node's
heartbeat, matches responses to requests, and turns what the nodes say on their own
(emergency frames, a reboot, a node that falls silent) into latched faults, so the rig goes
safe. Heartbeats run on the wall clock: they are about the wire and the host being alive,
not about rig time. ``NodeClient`` is one node as seen from a device driver.

Nodes listed in ``canopen_nodes`` speak CANopen (CiA 301, ``docs/canopen-plan.md``): the link
reads their heartbeat and EMCY itself and passes every frame of theirs to ``network`` (a
``canopen.Network`` over the same bus, fed by this link's notifier), where their
``drivers.canopen_client.CanopenClient`` does SDO and NMT. The host then also sends a CANopen
heartbeat as node 0x7F. Frames of node ids the rig does not use (their boot-up and heartbeat
too) are ignored.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence

import can
import canopen

from drivers import can_protocol as cp
from drivers import canopen_frames as cf
from drivers.errors import (
    DeviceLost,
    DeviceTimeout,
    DriverError,
    InterlockError,
    NodeError,
    NodeReset,
    ProtocolError,
    SetpointRangeError,
)
from drivers.faults import FaultLatch

log = logging.getLogger(__name__)


class CanLink:
    def __init__(self, bus: can.BusABC, nodes: list[str], *, faults: FaultLatch | None = None,
                 heartbeat_period_s: float = 0.1, node_timeout_s: float = 1.0, reply_timeout_s: float = 0.5,
                 channel: str = "", monotonic: Callable[[], float] = time.monotonic,
                 canopen_nodes: Sequence[str] = ()) -> None:
        unknown = [n for n in nodes if n not in cp.NODES]
        if unknown:
            raise ValueError(f"unknown CAN node(s) {unknown}; known: {', '.join(cp.NODES)}")
        stray = [n for n in canopen_nodes if n not in nodes]
        if stray:
            raise ValueError(f"CANopen node(s) {stray} are not among the rig's nodes {nodes}")
        self.bus = bus
        self.channel = channel or str(getattr(bus, "channel_info", "CAN"))
        self.faults = faults or FaultLatch()
        self.nodes = list(nodes)
        self.heartbeat_period_s = heartbeat_period_s
        self.node_timeout_s = node_timeout_s
        self.reply_timeout_s = reply_timeout_s
        #: the clock of every deadline here: the wall's, or one that leaves out the host's pauses
        #: (``drivers.runclock``) for nodes that run in this process
        self._mono = monotonic
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._pending: dict[tuple[int, int], list] = {}
        self._seq = dict.fromkeys(cp.NODES.values(), 0)
        self._last_hb: dict[int, float] = {}
        self._operational: set[int] = set()
        self._lost: set[int] = set()
        self._counter = 0
        #: node ids that speak CANopen, and every node id this rig uses
        self._co_ids = {cp.NODES[n] for n in canopen_nodes}
        self._used_ids = {cp.NODES[n] for n in nodes}
        self._foreign_seen: set[int] = set()
        #: the CANopen side of the bus: SDO clients and NMT of the CANopen nodes live here
        self.network = canopen.Network(bus)
        self._stop = threading.Event()
        #: When the host cannot reach a node to make it safe, it stops its heartbeat: every
        #: node's watchdog then trips and the nodes go safe by themselves.
        self.heartbeat_suspended = False
        self._notifier = can.Notifier(bus, [self._on_message], timeout=0.05)
        self._hb_thread = threading.Thread(target=self._heartbeat_loop, name="can-heartbeat", daemon=True)
        self._hb_thread.start()

    # ------------------------------------------------------------------ receive
    def _on_message(self, msg: can.Message) -> None:
        try:
            self._handle(msg)
        except Exception:  # the notifier thread must survive anything a frame can do
            log.exception("CAN receive handler failed on %s", msg)

    def _handle(self, msg: can.Message) -> None:
        if msg.is_error_frame:
            log.warning("CAN %s: bus error frame %s", self.channel, msg)
            return
        node = cf.node_of(msg.arbitration_id)
        if not msg.is_extended_id and msg.arbitration_id <= 0x7FF:
            if node in self._co_ids and msg.arbitration_id != node:
                self._handle_canopen(msg)
                return
            if node not in self._used_ids and msg.arbitration_id != cp.HOST_HEARTBEAT_ID:
                self._foreign(msg)
                return
        try:
            m = cp.decode(msg.arbitration_id, msg.data, msg.is_extended_id)
        except ProtocolError as exc:
            ours = any(msg.arbitration_id == base + cp.NODES[n]
                       for n in self.nodes for base in (cp.RESPONSE_BASE, cp.HEARTBEAT_BASE, cp.EMCY_BASE))
            if ours:
                self.faults.report(ProtocolError(f"CAN {self.channel}: {exc}"))
            else:
                log.warning("CAN %s: ignored foreign frame: %s", self.channel, exc)
            return
        if m.node and cp.NODE_NAMES[m.node] not in self.nodes:
            return  # a node this rig does not use (a motorized table when the table is manual)
        if isinstance(m, cp.Response):
            with self._lock:
                slot = self._pending.get((m.node, m.seq))
                if slot is not None:
                    slot[1] = m
                    slot[0].set()
                    return
            log.warning("CAN %s: unexpected response %s (late or duplicate)", self.channel, m)
        elif isinstance(m, cp.Heartbeat):
            if m.node == 0:
                return  # another host's heartbeat (or our own echo)
            self._on_heartbeat(m)
        elif isinstance(m, cp.Emergency):
            name = cp.NODE_NAMES[m.node]
            self.faults.report(NodeError(f"CAN node '{name}' (id {m.node}) reports an error: {m.text()} "
                                         f"(code 0x{m.code:04x}, detail {m.detail}); the rig went safe",
                                         node=name, code=m.code))

    def _foreign(self, msg: can.Message) -> None:
        """A frame of a node id this rig does not use (another device's boot-up, heartbeat,
        PDO, SDO, NMT or SYNC): not ours, ignored; said once per identifier."""
        first = msg.arbitration_id not in self._foreign_seen
        self._foreign_seen.add(msg.arbitration_id)
        log.log(logging.INFO if first else logging.DEBUG, "CAN %s: ignored frame 0x%03x of node %d, which this "
                "rig does not use (%d bytes)", self.channel, msg.arbitration_id, cf.node_of(msg.arbitration_id),
                len(msg.data))

    def _handle_canopen(self, msg: can.Message) -> None:
        """A frame from a CANopen node of this rig: to the ``canopen`` network (SDO answers),
        and its heartbeat and EMCY to the watch."""
        function = msg.arbitration_id & 0x780
        if function == 0x580 and len(msg.data) != 8:   # CiA 301: every SDO frame carries 8 bytes
            self.faults.report(ProtocolError(f"CAN {self.channel}: SDO answer 0x{msg.arbitration_id:03x} of node "
                                             f"'{cp.NODE_NAMES[cf.node_of(msg.arbitration_id)]}': "
                                             f"{len(msg.data)} data bytes (expected 8)"))
            return
        self.network.notify(msg.arbitration_id, msg.data, msg.timestamp)
        try:
            if function == 0x700:
                self._on_co_heartbeat(cf.decode_heartbeat(msg.arbitration_id, msg.data))
            elif function == 0x080:
                self._on_co_emergency(cf.decode_emergency(msg.arbitration_id, msg.data))
        except ProtocolError as exc:
            self.faults.report(ProtocolError(f"CAN {self.channel}: {exc}"))

    def _on_co_heartbeat(self, m: cf.CoHeartbeat) -> None:
        name = cp.NODE_NAMES[m.node]
        self._last_hb[m.node] = self._mono()
        was_up = m.node in self._operational
        if m.state == cf.NMT_OPERATIONAL:
            self._operational.add(m.node)
        elif m.state == cf.NMT_BOOT and was_up:
            self._operational.discard(m.node)
            self.faults.report(NodeReset(f"CAN node '{name}' (id {m.node}) rebooted (CANopen boot-up) and lost "
                                         f"its set-points; the rig went safe"))
        elif was_up:
            self._operational.discard(m.node)
            self.faults.report(NodeError(f"CAN node '{name}' (id {m.node}) left the operational state by itself "
                                         f"(now {m.text()})", node=name))

    def _on_co_emergency(self, m: cf.CoEmergency) -> None:
        name = cp.NODE_NAMES[m.node]
        if m.code == cf.EMCY_ERROR_RESET:
            log.info("CAN node '%s' (id %d): error reset (EMCY 0x0000)", name, m.node)
            return
        self.faults.report(NodeError(f"CAN node '{name}' (id {m.node}) reports an error: {m.text()} "
                                     f"(EMCY 0x{m.code:04x}, error register 0x{m.register:02x}, "
                                     f"data {m.data.hex()}); the rig went safe", node=name, code=m.code))

    def _on_heartbeat(self, m: cp.Heartbeat) -> None:
        name = cp.NODE_NAMES[m.node]
        self._last_hb[m.node] = self._mono()
        was_up = m.node in self._operational
        if m.state == cp.HB_OPERATIONAL:
            self._operational.add(m.node)
        elif m.state == cp.HB_BOOT and was_up:
            self._operational.discard(m.node)
            self.faults.report(NodeReset(f"CAN node '{name}' (id {m.node}) rebooted and lost its set-points; "
                                         f"the rig went safe"))
        elif m.state == cp.HB_SAFE and was_up:
            self._operational.discard(m.node)
            self.faults.report(NodeError(f"CAN node '{name}' (id {m.node}) latched its safe state by itself",
                                         node=name))

    # ------------------------------------------------------------------ heartbeat and watch
    def _heartbeat_loop(self) -> None:
        t_start = self._mono()
        while True:  # the first heartbeat goes out at once: it arms the nodes' watchdogs
            self._counter += 1
            try:
                if not self.heartbeat_suspended:
                    self._send(*cp.encode_heartbeat(cp.Heartbeat(0, cp.HB_OPERATIONAL, 0, self._counter)))
                    if self._co_ids:
                        self._send(cf.HOST_HEARTBEAT_COB, bytes([cf.NMT_OPERATIONAL]))
            except DeviceLost as exc:
                self.faults.report(exc)
                return
            now = self._mono()
            for name in self.nodes:
                node = cp.NODES[name]
                last = self._last_hb.get(node, t_start)
                if node not in self._lost and now - last > self.node_timeout_s:
                    self._lost.add(node)
                    self._operational.discard(node)
                    self.faults.report(DeviceLost(
                        f"CAN node '{name}' (id {node}) is silent: no heartbeat for {now - last:.1f} s "
                        f"(limit {self.node_timeout_s:g} s); check its cable and power; the rig went safe"))
            if self._stop.wait(self.heartbeat_period_s):
                return

    def wait_for_nodes(self, timeout_s: float = 2.0) -> None:
        """Block until every node has sent a heartbeat; DeviceLost names the missing ones."""
        deadline = self._mono() + timeout_s
        while True:
            missing = [n for n in self.nodes if cp.NODES[n] not in self._last_hb]
            if not missing:
                return
            if self._mono() > deadline:
                raise DeviceLost(f"CAN {self.channel}: no heartbeat from node(s) "
                                 f"{', '.join(f'{n} (id {cp.NODES[n]})' for n in missing)} within {timeout_s:g} s; "
                                 f"check the bus wiring, termination and node power")
            time.sleep(0.01)

    def mark_operational(self, name: str) -> None:
        self._operational.add(cp.NODES[name])

    # ------------------------------------------------------------------ send / request
    def _send(self, arbitration_id: int, data: bytes) -> None:
        msg = can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False)
        try:
            with self._send_lock:
                self.bus.send(msg, timeout=self.reply_timeout_s)
        except (can.CanError, OSError, ValueError) as exc:
            raise DeviceLost(f"CAN {self.channel}: cannot send frame 0x{arbitration_id:03x} ({exc}); "
                             f"is the interface up?") from exc

    def request(self, name: str, op: int, index: int = 0, value: int = 0,
                timeout_s: float | None = None) -> cp.Response:
        node = cp.NODES[name]
        timeout_s = self.reply_timeout_s if timeout_s is None else timeout_s
        with self._lock:
            seq = self._seq[node] = (self._seq[node] + 1) & 0xFF
            slot = self._pending[(node, seq)] = [threading.Event(), None]
        try:
            try:
                self._send(*cp.encode_request(cp.Request(node, seq, op, index, value)))
            except DeviceLost as exc:
                self.faults.report(exc)
                raise
            deadline = self._mono() + timeout_s
            while not slot[0].wait(0.05):
                if self._mono() <= deadline:
                    continue
                fault: DriverError = DeviceTimeout(f"CAN node '{name}' (id {node}) did not answer {cp.OPS[op]} "
                                                   f"index {index} within {timeout_s:g} s; the rig went safe")
                self.faults.report(fault)
                raise fault
        finally:
            with self._lock:
                self._pending.pop((node, seq), None)
        resp: cp.Response = slot[1]
        if resp.op != op or resp.index != index:
            fault = ProtocolError(f"CAN node '{name}' answered {cp.OPS.get(resp.op, resp.op)} index {resp.index} "
                                  f"to {cp.OPS[op]} index {index} (seq {seq})")
            self.faults.report(fault)
            raise fault
        return resp

    def close(self) -> None:
        self._stop.set()
        self._hb_thread.join(timeout=1.0)
        try:
            self._notifier.stop(timeout=1.0)
        finally:
            self.bus.shutdown()


class NodeClient:
    """One node as a device driver sees it: checked requests, typed refusals."""

    def __init__(self, link: CanLink, name: str) -> None:
        self.link = link
        self.name = name
        self.node_id = cp.NODES[name]

    def call(self, op: int, index: int = 0, value: int = 0, *, what: str = "", check_faults: bool = True) -> int:
        """Send a request; return the node's read-back value or raise its refusal as a typed error."""
        if check_faults:
            self.link.faults.check()
        resp = self.link.request(self.name, op, index, value)
        if resp.status == cp.ST_OK:
            return resp.value
        what = what or f"{cp.OPS[op]} index {index} value {value}"
        text = f"CAN node '{self.name}' refused {what}: {cp.STATUS_TEXT[resp.status]}"
        if resp.status == cp.ST_RANGE:
            raise SetpointRangeError(text, value=value)
        if resp.status in (cp.ST_INTERLOCK, cp.ST_LATCHED, cp.ST_NOT_HELD):
            raise InterlockError(text, detail=resp.value)
        fault = ProtocolError(text)
        self.link.faults.report(fault)
        raise fault

    def identify(self) -> int:
        """Check the node is the kind expected; return its firmware version."""
        value = self.call(cp.OP_IDENT, check_faults=False)
        kind = (value >> 16) & 0xFF
        if kind != cp.NODE_TYPES[self.name]:
            names = {v: k for k, v in cp.NODE_TYPES.items()}
            raise ProtocolError(f"CAN node id {self.node_id} identifies as '{names.get(kind, hex(kind))}', "
                                f"expected '{self.name}'; check the node ids")
        return value & 0xFFFF

    def clear(self) -> None:
        """Clear a latched or freshly booted node. From its answer on it counts as up, so a
        reboot is caught even before its first operational heartbeat arrives."""
        self.call(cp.OP_CLEAR, check_faults=False)
        self.link.mark_operational(self.name)

    def safe(self) -> None:
        self.call(cp.OP_SAFE, check_faults=False)

    def raw_get(self, index: int) -> int:
        """GET ``index`` as the node has it, while a fault is latched too (the safe state's read-back)."""
        return self.call(cp.OP_GET, index, check_faults=False)
