"""The simulated CAN nodes: the device side of docs/protocol.md section 2, on a python-can bus.

Each node keeps its registers, answers every request with a read-back, sends a heartbeat,
and watches the host's: when that stops for longer than the watchdog time, the node goes
to its safe values by itself, latches, and says so in an emergency frame. Settings reach
the physics through ``server.submit``, at the next block boundary.

``inject`` makes a node misbehave on request: ``stall`` (no answers, heartbeat goes on),
``disconnect`` (silent both ways), ``reset`` (reboot to power-on values), ``error`` (an
emergency frame; the node latches safe), ``bad_response`` (the next answer is malformed),
``busy`` (every answer ``delay_s`` late, as from a host too loaded to schedule the node's thread).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Collection
from typing import TYPE_CHECKING

import can

from drivers import can_protocol as cp
from drivers.errors import ProtocolError
from simhw.canopen_nodes import CANOPEN_NODE_CLASSES, CanopenDacNode, CanopenSimNode
from simhw.params import AXES, GYRO_CHANNELS

if TYPE_CHECKING:
    from simhw.rig_server import SimRigServer

log = logging.getLogger(__name__)

FIRMWARE = 0x0100
DAC_RANGE_V = 10.0
DAC_LSB_V = 2 * DAC_RANGE_V / 2 ** 16
NODE_FAULTS = ("stall", "disconnect", "reset", "error", "bad_response", "busy")


class SimNode:
    name = ""

    def __init__(self, server: SimRigServer) -> None:
        self.server = server
        self.node_id = cp.NODES[self.name]
        self.latched = False
        self.booting = True  # announces BOOT until the host's CLEAR
        self.stalled = False
        self.reply_delay_s = 0.0
        self.connected = True
        self.silent_since = 0.0
        self.bad_response = 0
        self.attach()

    def attach(self) -> None:
        """The node as the host finds it when the rig is opened."""
        self.power_on()

    # Subclasses: registers, their safe values, and requests.
    def power_on(self) -> None:
        self.go_safe()

    def go_safe(self) -> None:
        raise NotImplementedError

    def on_request(self, req: cp.Request) -> tuple[int, int]:
        raise NotImplementedError

    def handle(self, req: cp.Request) -> tuple[int, int]:
        if req.op == cp.OP_IDENT:
            return cp.ST_OK, (cp.NODE_TYPES[self.name] << 16) | FIRMWARE
        if req.op == cp.OP_CLEAR:
            self.latched = self.booting = False
            return cp.ST_OK, 0
        if req.op == cp.OP_SAFE:
            self.go_safe()
            return cp.ST_OK, 0
        if (self.latched or self.booting) and req.op not in (cp.OP_GET, cp.OP_STATUS):
            return cp.ST_LATCHED, 0
        return self.on_request(req)

    @property
    def hb_state(self) -> int:
        if self.booting:
            return cp.HB_BOOT  # repeated, so one lost frame cannot hide a reboot
        return cp.HB_SAFE if self.latched else cp.HB_OPERATIONAL

    @property
    def hb_flags(self) -> int:
        return 0


def _dac_quantize(micro_volts: int) -> tuple[bool, int, float]:
    v = cp.from_micro(micro_volts)
    if abs(v) > DAC_RANGE_V:
        return False, 0, 0.0
    code = max(-32768, min(32767, round(v / DAC_LSB_V)))
    back = code * DAC_LSB_V
    return True, cp.to_micro(back), back


class RelayNode(SimNode):
    """Mode register, select switches, hold; the interlocks of modes 4 and 5 (Ch. II D)."""

    name = "relay"

    def attach(self) -> None:
        # The rig may have been running for hours: the register holds the mode in force, and
        # the clamp (a mechanism, not a register) is where it was left.
        self.mode = self.selected = self.server.sim.mode
        self.clamped = self.server.sim.clamped
        self.held = self.alarm = False

    def go_safe(self) -> None:
        # mode 1 is allowed clamped or not: the safe state never moves the clamp
        self.mode = self.selected = 1
        self.held = self.alarm = False
        self.server.submit(lambda sim: sim.set_mode(1))

    def _commands_zero(self) -> bool:
        """The node senses the command DAC outputs (V_Td, gamma_c) on its interlock lines."""
        command = self.server.nodes.nodes["command"]     # the rig's own protocol or CANopen
        assert isinstance(command, CommandNode | CanopenDacNode)
        return not any(command.values.values())

    @property
    def hb_flags(self) -> int:
        return cp.HB_FLAG_ALARM if self.alarm else 0

    def status_word(self) -> int:
        snap = self.server.snapshot
        w = (self.mode << cp.ST_MODE_SHIFT) | (self.selected << cp.ST_SELECT_SHIFT)
        w |= (cp.ST_HELD if self.held else 0) | (cp.ST_ALARM if self.alarm else 0)
        w |= cp.ST_CLAMPED if self.clamped else 0
        for i, c in enumerate(GYRO_CHANNELS):
            w |= int(snap.at_speed) << (cp.ST_AT_SPEED_SHIFT + i)
            w |= int(snap.caged[c]) << (cp.ST_CAGED_SHIFT + i)
        return w | (min(100, int(snap.spin * 100)) << cp.ST_SPIN_SHIFT)

    def on_request(self, req: cp.Request) -> tuple[int, int]:
        if req.op == cp.OP_HOLD:
            self.held, self.selected = True, self.mode
            return cp.ST_OK, self.mode
        if req.op == cp.OP_SELECT:
            if not self.held:
                return cp.ST_NOT_HELD, self.mode
            if not 1 <= req.value <= 6:
                self.alarm = True  # the register is not clocked; the lamp lights
                return cp.ST_RANGE, self.selected
            self.selected, self.alarm = req.value, False
            return cp.ST_OK, self.selected
        if req.op == cp.OP_RELEASE:
            if not self.held:
                return cp.ST_NOT_HELD, self.mode
            self.held = False
            m = self.selected
            if self.clamped and m not in cp.CLAMP_MODES:
                self.selected = self.mode
                return cp.ST_INTERLOCK, cp.WHY_CLAMPED
            if m in (4, 5):
                snap = self.server.snapshot
                need = ("X", "Y", "Z", "XRD") if m == 4 else ("X", "Y", "XRD")
                why = (0 if snap.at_speed else cp.WHY_NOT_AT_SPEED) | (
                    0 if all(snap.caged[c] for c in need) else cp.WHY_NOT_CAGED)
                if why:
                    self.selected = self.mode
                    return cp.ST_INTERLOCK, why
            if m != self.mode:
                self.mode = m
                self.server.submit(lambda sim: sim.set_mode(m))
            return cp.ST_OK, self.mode
        if req.op == cp.OP_STATUS:
            return cp.ST_OK, self.status_word()
        if req.op == cp.OP_CLAMP:
            return self._clamp(req.value)
        if req.op == cp.OP_GET and req.index == 0:
            return cp.ST_OK, self.mode
        if req.op == cp.OP_GET and req.index == 1:
            return cp.ST_OK, int(self.clamped)
        return (cp.ST_BAD_INDEX if req.op == cp.OP_GET else cp.ST_BAD_OP), 0


    def _clamp(self, value: int) -> tuple[int, int]:
        """CLAMP 1 / 0 (docs/protocol.md): clamping needs mode 1-3 and the command inputs at
        zero; releasing needs the command inputs at zero (a torque waiting on an opened drive
        would kick the platform the moment the loop closes)."""
        if value not in (0, 1):
            return cp.ST_RANGE, int(self.clamped)
        on = bool(value)
        if on == self.clamped:
            return cp.ST_OK, int(on)
        why = 0 if self._commands_zero() else cp.WHY_COMMAND
        if on and (self.mode not in cp.CLAMP_MODES or (self.held and self.selected not in cp.CLAMP_MODES)):
            why |= cp.WHY_MODE
        if why:
            return cp.ST_INTERLOCK, why
        self.clamped = on
        self.server.submit(lambda sim: sim.set_clamp(on))
        return cp.ST_OK, int(on)


class CagingNode(SimNode):
    name = "caging"

    def go_safe(self) -> None:
        self.inhibit = dict.fromkeys(GYRO_CHANNELS, False)

        def apply(sim) -> None:
            for c in GYRO_CHANNELS:
                sim.set_caging_inhibit(c, False)
        self.server.submit(apply)

    def on_request(self, req: cp.Request) -> tuple[int, int]:
        if req.index >= len(GYRO_CHANNELS):
            return cp.ST_BAD_INDEX, 0
        ch = GYRO_CHANNELS[req.index]
        if req.op == cp.OP_SET:
            if req.value not in (0, 1):
                return cp.ST_RANGE, int(self.inhibit[ch])
            on = bool(req.value)
            self.inhibit[ch] = on
            self.server.submit(lambda sim: sim.set_caging_inhibit(ch, on))
            return cp.ST_OK, int(on)
        if req.op == cp.OP_GET:
            return cp.ST_OK, int(self.inhibit[ch])
        return cp.ST_BAD_OP, 0


class _DacNode(SimNode):
    outputs: tuple[str, ...] = ()

    def go_safe(self) -> None:
        self.values = dict.fromkeys(self.outputs, 0)
        for out in self.outputs:
            self._apply(out, 0.0)

    def _apply(self, output: str, volts: float) -> None:
        raise NotImplementedError

    def on_request(self, req: cp.Request) -> tuple[int, int]:
        if req.index >= len(self.outputs):
            return cp.ST_BAD_INDEX, 0
        out = self.outputs[req.index]
        if req.op == cp.OP_SET:
            ok, micro, volts = _dac_quantize(req.value)
            if not ok:
                return cp.ST_RANGE, self.values[out]
            self.values[out] = micro
            self._apply(out, volts)
            return cp.ST_OK, micro
        if req.op == cp.OP_GET:
            return cp.ST_OK, self.values[out]
        return cp.ST_BAD_OP, 0


class TorquerNode(_DacNode):
    name = "torquer"
    outputs = GYRO_CHANNELS

    def _apply(self, output: str, volts: float) -> None:
        self.server.submit(lambda sim: sim.set_torquer_bias_V(output, volts))


class CommandNode(_DacNode):
    name = "command"
    outputs = tuple(f"vtd_{a}" for a in AXES) + tuple(f"gc_{a}" for a in AXES)

    def _apply(self, output: str, volts: float) -> None:
        kind, axis = output.split("_")
        if kind == "vtd":
            self.server.submit(lambda sim: sim.set_command_torque_V(axis, volts))
        else:
            self.server.submit(lambda sim: sim.set_ac_bias_V(axis, volts))


class TableNode(SimNode):
    """A motorized rotary table; it reaches the commanded angle at the next block."""

    name = "table"

    def power_on(self) -> None:
        t = self.server.sim.cfg.table
        self.tilt, self.spindle = cp.to_micro(t.tilt_deg), cp.to_micro(t.spindle_deg % 360.0)

    def go_safe(self) -> None:
        pass  # a table at rest is safe where it is

    def on_request(self, req: cp.Request) -> tuple[int, int]:
        if req.op == cp.OP_SET and req.index == 0:
            deg = cp.from_micro(req.value)
            if not 0.0 <= deg <= 90.0:
                return cp.ST_RANGE, self.tilt
            self.tilt = req.value
            self.server.submit(lambda sim: sim.set_table(tilt_deg=deg))
            return cp.ST_OK, self.tilt
        if req.op == cp.OP_SET and req.index == 1:
            deg = cp.from_micro(req.value) % 360.0
            self.spindle = cp.to_micro(deg)
            self.server.submit(lambda sim: sim.set_table(spindle_deg=deg))
            return cp.ST_OK, self.spindle
        if req.op == cp.OP_GET and req.index in (0, 1, 2):
            return cp.ST_OK, (self.tilt, self.spindle, 0)[req.index]
        return (cp.ST_BAD_INDEX if req.op in (cp.OP_GET, cp.OP_SET) else cp.ST_BAD_OP), 0


NODE_CLASSES = (RelayNode, CagingNode, TorquerNode, CommandNode, TableNode)


class CanNodeHost:
    """All simulated nodes on one virtual bus: a receive thread and a heartbeat/watchdog thread."""

    def __init__(self, server: SimRigServer, channel: str, heartbeat_period_s: float = 0.1,
                 watchdog_s: float = 1.0, monotonic: Callable[[], float] = time.monotonic,
                 external: Collection[str] = (), canopen: Collection[str] = ()) -> None:
        self.server = server
        self._mono = monotonic          # the watchdogs' clock (``SimRigServer.monotonic``)
        self.channel = channel
        self.heartbeat_period_s = heartbeat_period_s
        self.watchdog_s = watchdog_s
        self.bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        #: ``external``: nodes left to a device the caller runs on the same bus (not simulated here)
        #: ``canopen``: nodes simulated as CANopen slaves (``simhw.canopen_nodes``), each on a
        #: network of its own; the rest speak the rig's own protocol through this host's threads
        self._own: dict[str, SimNode] = {n.name: n for n in (cls(server) for cls in NODE_CLASSES
                                                              if cls.name not in external and cls.name not in canopen)}
        self.canopen_nodes: dict[str, CanopenSimNode] = {}
        for name in canopen:
            if name in external:
                continue
            if name not in CANOPEN_NODE_CLASSES:
                raise ValueError(f"the simulated {name} node does not speak CANopen yet "
                                 f"(only {', '.join(CANOPEN_NODE_CLASSES)})")
            self.canopen_nodes[name] = CANOPEN_NODE_CLASSES[name](server, channel, watchdog_s, monotonic)
        #: every simulated node by name (tests look at their registers)
        self.nodes: dict[str, SimNode | CanopenSimNode] = {**self._own, **self.canopen_nodes}
        self._by_id = {n.node_id: n for n in self._own.values()}
        self._last_host_hb: float | None = None  # watchdogs arm on the first host heartbeat
        self._counter = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._rx_loop, name="sim-can-rx", daemon=True),
                         threading.Thread(target=self._hb_loop, name="sim-can-heartbeat", daemon=True)]
        for t in self._threads:
            t.start()

    def inject(self, node: str, fault: str, code: int = cp.EMCY_OVERTEMP, delay_s: float = 1.5) -> None:
        if node not in self.nodes:
            raise ValueError(f"unknown node {node!r} (one of {', '.join(self.nodes)})")
        if fault not in NODE_FAULTS:
            raise ValueError(f"unknown node fault {fault!r} (one of {', '.join(NODE_FAULTS)})")
        if node in self.canopen_nodes:
            self.canopen_nodes[node].inject(fault, code, delay_s)
            return
        n = self._own[node]
        with self._lock:
            if fault == "stall":
                n.stalled = True
            elif fault == "busy":
                n.reply_delay_s = float(delay_s)
            elif fault == "disconnect":
                n.connected = False
                n.silent_since = self._mono()
            elif fault == "bad_response":
                n.bad_response += 1
            elif fault == "reset":
                n.latched = False
                n.booting = True
                n.power_on()
                self._send(*cp.encode_heartbeat(cp.Heartbeat(n.node_id, cp.HB_BOOT, 0, 0)))
            elif fault == "error":
                n.go_safe()
                n.latched = True
                self._send(*cp.encode_emergency(cp.Emergency(n.node_id, code, 0, 0, 0)))

    def _send(self, arbitration_id: int, data: bytes) -> None:
        try:
            self.bus.send(can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False))
        except can.CanError as exc:
            log.warning("simulated CAN node send failed: %s", exc)

    def _rx_loop(self) -> None:
        while not self._stop.is_set():
            try:
                msg = self.bus.recv(0.05)
            except can.CanError:
                return
            if msg is None:
                continue
            try:
                m = cp.decode(msg.arbitration_id, msg.data, msg.is_extended_id)
            except ProtocolError as exc:
                self._refuse(msg, exc)
                continue
            if isinstance(m, cp.Heartbeat) and m.node == 0:
                self._last_host_hb = self._mono()
            elif isinstance(m, cp.Request):
                self._answer(m)

    def _refuse(self, msg: can.Message, exc: ProtocolError) -> None:
        """A request-shaped frame with an unknown opcode is answered BAD_OP; other junk is ignored."""
        node = msg.arbitration_id - cp.REQUEST_BASE
        n = self._by_id.get(node)
        if n is None:   # another device's frame (a CANopen node's SDO, NMT, heartbeat): not ours
            log.debug("simulated CAN nodes: ignored frame not for them: %s", exc)
            return
        if msg.is_extended_id or len(msg.data) != 8 or not n.connected or n.stalled:
            log.warning("simulated CAN nodes: ignored bad frame: %s", exc)
            return
        data = bytearray(msg.data)
        data[3] = cp.ST_BAD_OP
        self._send(cp.RESPONSE_BASE + node, bytes(data))

    def _answer(self, req: cp.Request) -> None:
        delay = getattr(self._by_id.get(req.node), "reply_delay_s", 0.0)
        if delay:
            time.sleep(delay)           # outside the lock: the heartbeats go on, as on a busy host
        with self._lock:
            n = self._by_id.get(req.node)
            if n is None or not n.connected or n.stalled:
                return
            try:
                status, value = n.handle(req)
            except Exception:  # a node answers, it does not die
                log.exception("simulated node %s failed on %s", n.name, req)
                status, value = cp.ST_BAD_OP, 0
            arb, data = cp.encode_response(cp.Response(req.node, req.seq, req.op, req.index, status, value))
            if n.bad_response:
                n.bad_response -= 1
                data = data[:5]
            self._send(arb, data)

    def _hb_loop(self) -> None:
        while not self._stop.wait(self.heartbeat_period_s):
            self._counter += 1
            now = self._mono()
            with self._lock:
                for n in self._own.values():
                    if not n.connected:
                        # Off the bus it hears no host either: its watchdog trips, silently.
                        if not n.latched and now - n.silent_since > self.watchdog_s:
                            n.go_safe()
                            n.latched = True
                        continue
                    host_gone = self._last_host_hb is not None and now - self._last_host_hb > self.watchdog_s
                    if host_gone and not n.latched:
                        log.warning("simulated node %s: host heartbeat lost, going safe", n.name)
                        n.go_safe()
                        n.latched = True
                        self._send(*cp.encode_emergency(cp.Emergency(n.node_id, cp.EMCY_HEARTBEAT_LOST, 0, 0, 0)))
                    self._send(*cp.encode_heartbeat(cp.Heartbeat(n.node_id, n.hb_state, n.hb_flags, self._counter)))

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=1.0)
        for co in self.canopen_nodes.values():
            co.close()
        self.bus.shutdown()
