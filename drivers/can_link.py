"""The host's end of the CAN bus: the CANopen network, heartbeats both ways, the watch.

``CanLink`` owns a python-can bus and a ``canopen.Network`` over it, fed by the link's own
notifier; each node's ``drivers.canopen_client.CanopenClient`` does SDO and NMT there. Every
rig node is a CANopen device (CiA 301, ``docs/protocol.md`` section 2): the link sends the
host heartbeat as node 0x7F, which arms each node's heartbeat consumer (its watchdog), reads
the nodes' heartbeat and EMCY itself, and turns what the nodes say on their own (an EMCY, a
reboot, leaving the operational state, falling silent) into latched faults, so the rig goes
safe. Frames of node ids the rig does not use (their boot-up and heartbeat too) are ignored.
A node's silence counts from when the host set its heartbeat period (``watch``); its EMCY is a
fault from the host's NMT start on (``started``). With ``listen_s`` the link first listens for
another host's heartbeat and refuses the bus if it hears one (``drivers.claim``).
The host heartbeat goes out every ``heartbeat_period_s`` of wall time; a node's silence is
measured on the link's deadline clock (``monotonic``): both are about the wire and the host
being alive, not about rig time.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence

import can
import canopen

from drivers import canopen_frames as cf
from drivers import rig_nodes as rn
from drivers.errors import (
    DeviceLost,
    DeviceTimeout,
    NodeError,
    NodeReset,
    ProtocolError,
    RigBusy,
)
from drivers.faults import FaultLatch

log = logging.getLogger(__name__)


class CanLink:
    def __init__(
        self,
        bus: can.BusABC,
        nodes: list[str],
        *,
        faults: FaultLatch | None = None,
        heartbeat_period_s: float = 0.1,
        node_timeout_s: float = 1.0,
        reply_timeout_s: float = 0.5,
        channel: str = "",
        monotonic: Callable[[], float] = time.monotonic,
        listen_s: float = 0.0,
    ) -> None:
        """``listen_s``: first listen that long, sending nothing, for another host's heartbeat
        (``0x77F``); one heard raises ``RigBusy`` (``drivers.claim``). A bus only this process
        can reach (the sim rig's) needs none."""
        #: every node's id by name, the devices of ``drivers.devices`` included
        self.ids = rn.node_ids()
        self.names = {i: n for n, i in self.ids.items()}
        unknown = [n for n in nodes if n not in self.ids]
        if unknown:
            raise ValueError(f"unknown CAN node(s) {unknown}; known: {', '.join(self.ids)}")
        self.bus = bus
        self.channel = channel or str(getattr(bus, "channel_info", "CAN"))
        self.faults = faults or FaultLatch()
        self.nodes = list(nodes)
        self.heartbeat_period_s = heartbeat_period_s
        self.node_timeout_s = node_timeout_s
        self.reply_timeout_s = reply_timeout_s
        #: the clock of every deadline here: the wall's, or one that leaves out the host's pauses
        #: (``drivers.runclock``) for nodes that run in this process
        self.monotonic = monotonic
        self._send_lock = threading.Lock()
        self._last_hb: dict[int, float] = {}
        #: nodes whose silence is a fault, since when: from the host's heartbeat settings on
        #: (a module at factory defaults may send none before)
        self._watched: dict[int, float] = {}
        #: nodes this host has NMT-started: an EMCY from one not yet started predates this
        #: connection (a trip at the previous session's end) and is not a fault of this one
        self._started: set[int] = set()
        self._other_host: can.Message | None = None
        self._operational: set[int] = set()
        self._lost: set[int] = set()
        #: every node id this rig uses
        self._used_ids = {self.ids[n] for n in nodes}
        self._foreign_seen: set[int] = set()
        #: SDO clients and NMT of the nodes live here
        self.network = canopen.Network(bus)
        self._stop = threading.Event()
        #: When the host cannot reach a node to make it safe, it stops its heartbeat: every
        #: node's watchdog then trips and the nodes go safe by themselves.
        self.heartbeat_suspended = False
        # the receive thread's poll period: close waits for it to notice (at 0.05 s, a part
        # of every sim rig's close)
        self._notifier = can.Notifier(bus, [self._on_message], timeout=0.01)
        self._hb_thread = threading.Thread(
            target=self._heartbeat_loop, name="can-heartbeat", daemon=True
        )
        if listen_s > 0:
            self._listen(listen_s)
        self._hb_thread.start()

    def _listen(self, listen_s: float) -> None:
        """Refuse a bus another host is driving, before this one sends a frame."""
        end = time.monotonic() + listen_s
        while self._other_host is None and time.monotonic() < end:
            time.sleep(0.01)
        if self._other_host is not None:
            try:
                self._notifier.stop(timeout=1.0)
            finally:
                self.bus.shutdown()
            raise RigBusy(
                f"CAN {self.channel}: another host is driving this bus (its heartbeat 0x{cf.HOST_HEARTBEAT_COB:03x} "
                f"was heard); this host sent nothing. Close the other session (or its PC's), then try again"
            )

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
        if (
            msg.arbitration_id == cf.HOST_HEARTBEAT_COB
            and not msg.is_extended_id
            and not self._hb_thread.is_alive()
        ):
            self._other_host = msg  # before this host's first heartbeat: another host's
        if msg.is_extended_id or node not in self._used_ids or msg.arbitration_id == node:
            # another device's frame, NMT and SYNC (node 0), a 29-bit frame: not ours
            self._foreign(msg)
            return
        function = msg.arbitration_id & 0x780
        if function == 0x580 and len(msg.data) != 8:  # CiA 301: every SDO frame carries 8 bytes
            self.faults.report(
                ProtocolError(
                    f"CAN {self.channel}: SDO answer 0x{msg.arbitration_id:03x} of node "
                    f"'{self.names[node]}': {len(msg.data)} data bytes (expected 8)"
                )
            )
            # passed on all the same: the transfer waiting for it fails now, not at its deadline
        # the project's own checks first: a frame the canopen package chokes on still latches
        try:
            if function == 0x700:
                self._on_heartbeat(cf.decode_heartbeat(msg.arbitration_id, msg.data))
            elif function == 0x080:
                self._on_emergency(cf.decode_emergency(msg.arbitration_id, msg.data))
        except ProtocolError as exc:
            self.faults.report(ProtocolError(f"CAN {self.channel}: {exc}"))
            return
        self.network.notify(msg.arbitration_id, msg.data, msg.timestamp)

    def _foreign(self, msg: can.Message) -> None:
        """A frame of a node id this rig does not use (another device's boot-up, heartbeat,
        PDO, SDO, NMT or SYNC): not ours, ignored; said once per identifier."""
        first = msg.arbitration_id not in self._foreign_seen
        self._foreign_seen.add(msg.arbitration_id)
        log.log(
            logging.INFO if first else logging.DEBUG,
            "CAN %s: ignored frame 0x%03x of node %d, which this rig does not use (%d bytes)",
            self.channel,
            msg.arbitration_id,
            cf.node_of(msg.arbitration_id),
            len(msg.data),
        )

    def _on_heartbeat(self, m: cf.CoHeartbeat) -> None:
        name = self.names[m.node]
        self._last_hb[m.node] = self.monotonic()
        was_up = m.node in self._operational
        if m.state == cf.NMT_OPERATIONAL:
            self._operational.add(m.node)
        elif m.state == cf.NMT_BOOT and was_up:
            self._operational.discard(m.node)
            self.faults.report(
                NodeReset(
                    f"CAN node '{name}' (id {m.node}) rebooted (CANopen boot-up) and lost "
                    f"its set-points; the rig went safe"
                )
            )
        elif was_up:
            self._operational.discard(m.node)
            self.faults.report(
                NodeError(
                    f"CAN node '{name}' (id {m.node}) left the operational state by itself "
                    f"(now {m.text()})",
                    node=name,
                )
            )

    def _on_emergency(self, m: cf.CoEmergency) -> None:
        name = self.names[m.node]
        if m.code == cf.EMCY_ERROR_RESET:
            log.info("CAN node '%s' (id %d): error reset (EMCY 0x0000)", name, m.node)
            return
        if m.node not in self._started:
            log.warning(
                "CAN node '%s' (id %d): EMCY 0x%04x (%s) before this host's NMT start: from before this "
                "connection (a node tripped at the previous session's end sits at its error values); "
                "not a fault of this one",
                name,
                m.node,
                m.code,
                m.text(),
            )
            return
        self.faults.report(
            NodeError(
                f"CAN node '{name}' (id {m.node}) reports an error: {m.text()} "
                f"(EMCY 0x{m.code:04x}, error register 0x{m.register:02x}, "
                f"data {m.data.hex()}); the rig went safe",
                node=name,
                code=m.code,
            )
        )

    # ------------------------------------------------------------------ heartbeat and watch
    def _heartbeat_loop(self) -> None:
        while True:  # the first heartbeat goes out at once: it arms the nodes' watchdogs
            try:
                if not self.heartbeat_suspended:
                    self._send(cf.HOST_HEARTBEAT_COB, bytes([cf.NMT_OPERATIONAL]))
            except DeviceLost as exc:
                self.faults.report(exc)
                return
            now = self.monotonic()
            for name in self.nodes:
                node = self.ids[name]
                since = self._watched.get(node)
                if since is None:
                    continue
                last = max(self._last_hb.get(node, since), since)
                if node not in self._lost and now - last > self.node_timeout_s:
                    self._lost.add(node)
                    self._operational.discard(node)
                    self.faults.report(
                        DeviceLost(
                            f"CAN node '{name}' (id {node}) is silent: no heartbeat for {now - last:.1f} s "
                            f"(limit {self.node_timeout_s:g} s); check its cable and power; the rig went safe"
                        )
                    )
            if self._stop.wait(self.heartbeat_period_s):
                return

    def watch(self, name: str) -> None:
        """From now on node ``name``'s silence for longer than the node timeout is a fault
        (called once the host has set the node's heartbeat period)."""
        self._watched.setdefault(self.ids[name], self.monotonic())

    def started(self, name: str) -> None:
        """The host has NMT-started node ``name``: from now on its EMCY frames are faults."""
        self._started.add(self.ids[name])

    def wait_for_nodes(self, timeout_s: float = 2.0) -> None:
        """Block until every node has sent a heartbeat; DeviceLost names the missing ones."""
        missing = self._wait(timeout_s, self.nodes, lambda node: node in self._last_hb)
        if missing:
            raise DeviceLost(
                f"CAN {self.channel}: no heartbeat from node(s) {missing} within {timeout_s:g} s; "
                f"check the bus wiring, termination and node power"
            )

    def wait_operational(self, names: Sequence[str], timeout_s: float) -> None:
        """Block until each node of ``names`` says operational in its heartbeat (after the
        host's NMT start, which is not answered); DeviceTimeout names the ones that do not.
        From then on a boot-up or a change of state of theirs is a fault."""
        missing = self._wait(timeout_s, names, lambda node: node in self._operational)
        if missing:
            raise DeviceTimeout(
                f"CAN {self.channel}: node(s) {missing} did not report the operational state "
                f"within {timeout_s:g} s of the NMT start; check their error register (0x1001)"
            )

    def _wait(self, timeout_s: float, names: Sequence[str], ready: Callable[[int], bool]) -> str:
        """Wait until ``ready`` holds for each node of ``names``; '' or the ones it does not hold for."""
        deadline = self.monotonic() + timeout_s
        while True:
            missing = [n for n in names if not ready(self.ids[n])]
            if not missing or self.monotonic() > deadline:
                return ", ".join(f"{n} (id {self.ids[n]})" for n in missing)
            time.sleep(0.01)

    # ------------------------------------------------------------------ send
    def _send(self, arbitration_id: int, data: bytes) -> None:
        msg = can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False)
        try:
            with self._send_lock:
                self.bus.send(msg, timeout=self.reply_timeout_s)
        except (can.CanError, OSError, ValueError) as exc:
            raise DeviceLost(
                f"CAN {self.channel}: cannot send frame 0x{arbitration_id:03x} ({exc}); "
                f"is the interface up?"
            ) from exc

    def close(self) -> None:
        self._stop.set()
        self._hb_thread.join(timeout=1.0)
        try:
            self._notifier.stop(timeout=1.0)
        finally:
            self.bus.shutdown()
