"""Simulated CAN nodes that speak CANopen (issue 21, ``docs/canopen-plan.md`` section 8).

Each one is the ``canopen`` package's ``LocalNode``, built from the node's EDS file. All of
them share one ``canopen.Network`` on the sim's virtual channel (``simhw.can_nodes``), as the
modules of a real rig share one bus; on the virtual channel a frame is handled in the
thread that sent it (``simhw.can_nodes``: five nodes each with its own network put ten thread
hand-offs into every SDO round trip, one network with its own receiving thread two). The
package gives the SDO server, the NMT slave and the EMCY producer. This module adds what CiA
301 and CiA 401 ask of the device and LocalNode lacks:
* a heartbeat producer whose frames leave in the order the state changed. LocalNode's is a
  python-can cyclic task: a frame it has taken up goes out with the state of that moment, so
  after an NMT start a frame sent at once with the new state could be followed by the task's
  frame with the old one, and the host saw a node that "left the operational state by
  itself" while it connected (one `make test` in a few). Here one thread sends every
  heartbeat, with the state as it is when the frame is built, at once on a change of state;
* the heartbeat consumer (0x1016), on the sim's deadline clock. When the host's heartbeat
  stops, the outputs go to their error values (0x6443/0x6444), EMCY 0x8130 is sent and the
  node goes pre-operational;
* value checks (SDO abort 0x06090030);
* the outputs' effect on the physics (``server.submit``);
* the fault injections of ``simhw.can_nodes`` (``NODE_FAULTS``).

The torquer and command DACs are CiA 401 analogue outputs, the caging switches CiA 401 digital
outputs, the relay driver and the rotary table manufacturer objects.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, cast

import canopen
from canopen.sdo.exceptions import SdoAbortedError

from drivers import canopen_frames as cf
from drivers import rig_nodes as rn
from drivers.caging import DO_8, DO_ERROR_MODE, DO_ERROR_VALUE
from drivers.canopen_client import (
    ABORT_INTERLOCK,
    ABORT_NOT_HELD,
    ABORT_NOT_OPERATIONAL,
    ABORT_RANGE,
)
from drivers.canopen_dac import AO_16, AO_ERROR_MODE, AO_ERROR_VALUE
from drivers.relay import R_CLAMP, R_MODE, R_REASONS, R_SAFE, R_SELECTED, R_STATUS, R_SWITCHES
from drivers.table import T_ACTUAL_SPINDLE, T_ACTUAL_TILT, T_MOVING, T_SPINDLE, T_TILT
from simhw.config import AXES, GYRO_CHANNELS

if TYPE_CHECKING:
    from simhw.rig_server import SimRigServer

log = logging.getLogger(__name__)

ABORT_VALUE_RANGE = ABORT_RANGE[0]
FULL_SCALE_V = 10.0
#: the bus receive thread's poll period (a channel other than python-can's virtual one), s:
#: closing the rig waits for it to notice
NOTIFIER_CYCLE_S = 0.01
#: the heartbeat byte of each of the package's NMT state names
NMT_CODES = {name: code for code, name in canopen.nmt.NMT_STATES.items()}
LSB_V = FULL_SCALE_V / 32768


class CanopenSimNode:
    """A simulated node as a CANopen slave: LocalNode from ``drivers/eds/<name>.eds``, the
    heartbeat consumer, error behaviour and fault injections. Subclasses give the outputs:
    ``reset_outputs``, ``error_outputs``, ``go_safe``, ``_on_write``."""

    name = ""

    def __init__(
        self,
        server: SimRigServer,
        network: canopen.Network,
        watchdog_s: float,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        self.server = server
        self.node_id = rn.node_ids()[self.name]
        self._mono = monotonic
        self.watchdog_s = watchdog_s
        self.network = network
        self.node = canopen.LocalNode(self.node_id, cf.object_dictionary(self.name, self.node_id))
        self.network.add_node(self.node)
        # the SDO server behind a gate, for the fault injections
        self.network.unsubscribe(0x600 + self.node_id, self.node.sdo.on_request)
        self.network.subscribe(0x600 + self.node_id, self._on_sdo)
        self._send_response = self.node.sdo.send_response
        setattr(self.node.sdo, "send_response", self._sdo_response)  # noqa: B010 - an instance's method replaced
        self.node.add_write_callback(self._on_write)
        self.node.add_read_callback(self._on_read)
        # receive PDOs as the EDS maps them (RPDO1: outputs 1-4, RPDO2: 5-6)
        self.node.rpdo.read(from_od=True)
        assert self.node.rpdo.map is not None
        for pdo_map in self.node.rpdo.map.values():
            pdo_map.add_callback(self._on_rpdo)
        self.node.rpdo.subscribe()
        #: each RPDO's objects and where they lie in its frame: the EDS's mapping, which the
        #: node keeps (a host's SDO write to 0x1600.. is stored, not applied)
        self._layouts = {id(m): self._rpdo_layout(m) for m in self.node.rpdo.map.values()}
        self.network.subscribe(0, self._on_nmt)
        self.network.subscribe(cf.HOST_HEARTBEAT_COB, self._on_host_heartbeat)
        #: True from a trip of the watchdog or an error until the host's NMT start
        self.latched = False
        self.stalled = False
        self.reply_delay_s = 0.0
        self.bad_response = 0
        self._connected = True
        self._last_host: float | None = None
        self._stop = threading.Event()
        #: answers held back by the ``busy`` fault, cancelled at close
        self._timers: list[threading.Timer] = []
        self._thread = threading.Thread(
            target=self._watch, name=f"sim-canopen-{self.name}", daemon=True
        )
        # the NMT slave's heartbeat calls come here (module docstring); 0 s: no heartbeat
        self._heartbeat_s = 0.0
        self._heartbeat_due = threading.Event()
        nmt = self.node.nmt
        setattr(nmt, "start_heartbeat", self._start_heartbeat)  # noqa: B010 - as send_response
        setattr(nmt, "stop_heartbeat", self._stop_heartbeat)  # noqa: B010
        setattr(nmt, "update_heartbeat", self._heartbeat_due.set)  # noqa: B010
        self._producer = threading.Thread(
            target=self._produce, name=f"sim-canopen-{self.name}-heartbeat", daemon=True
        )
        self.power_on()
        self._thread.start()
        self._producer.start()

    # ------------------------------------------------------------------ state
    def power_on(self) -> None:
        """Power-on values (outputs 0, the EDS's defaults), boot-up, then pre-operational."""
        self.node.data_store.clear()
        self.node.data_store[0x1016] = {
            1: ((cf.HOST_NODE_ID << 16) | round(self.watchdog_s * 1000)).to_bytes(4, "little")
        }
        self.reset_outputs()
        self._last_host = None
        self.node.nmt.send_command(0x81)  # reset node: boot-up frame ...
        self.node.nmt.send_command(0x80)  # ... pre-operational; heartbeat per 0x1017

    def reset_outputs(self) -> None:
        """Outputs to their power-on values, in the physics too (the data store is cleared)."""
        raise NotImplementedError

    def error_outputs(self) -> None:
        """Outputs to their error values (CiA 401 error mode / error value objects)."""
        raise NotImplementedError

    def go_safe(self) -> None:
        raise NotImplementedError

    def _on_write(
        self, index: int, subindex: int, od: canopen.objectdictionary.ODVariable, data: bytes
    ) -> None:
        """Check a written value (``SdoAbortedError`` refuses it) and apply it."""

    def _on_read(
        self, index: int, subindex: int, od: canopen.objectdictionary.ODVariable
    ) -> int | None:
        """An object the node computes when read (None: the data store's, or the EDS default)."""
        return None

    def get(self, index: int, sub: int) -> int:
        """An integer object as the node has it (through its own SDO server's view)."""
        value = cast(Any, self.node.sdo)[index][sub].raw
        assert isinstance(value, int)
        return value

    def set(self, index: int, sub: int, value: int) -> None:
        """Write an object as the node itself does (the write callbacks run)."""
        cast(Any, self.node.sdo)[index][sub].raw = value

    @property
    def connected(self) -> bool:
        return self._connected

    @connected.setter
    def connected(self, on: bool) -> None:
        self._connected = on
        if not on:
            self._stop_heartbeat()
            self._last_host = self._mono()  # off the bus: its watchdog runs out

    # ------------------------------------------------------------------ the bus
    def _on_sdo(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if self.reply_delay_s:
            # a host too busy to run the node's thread; the other nodes on the shared network
            # answer meanwhile (a sleep here would hold up the sender, and with it the bus)
            timer = threading.Timer(
                self.reply_delay_s, self._serve_sdo, (can_id, bytes(data), timestamp)
            )
            timer.daemon = True
            self._timers = [t for t in self._timers if t.is_alive()] + [timer]
            timer.start()
            return
        self._serve_sdo(can_id, data, timestamp)

    def _serve_sdo(self, can_id: int, data: bytes | bytearray, timestamp: float) -> None:
        if not self._connected or self.stalled or self._stop.is_set():
            return
        self.node.sdo.on_request(can_id, bytearray(data), timestamp)

    def _sdo_response(self, response: bytes | bytearray) -> None:
        if self.bad_response:
            self.bad_response -= 1
            response = bytes(response)[:5]
        self._send_response(response)

    def _on_rpdo(self, pdo_map: canopen.pdo.PdoMap) -> None:
        """A receive PDO: its outputs, as written by SDO, in the operational state only (CiA 301)."""
        if not self._connected or self.stalled or self.node.nmt.state != "OPERATIONAL":
            return
        store = self.node.data_store
        frame = pdo_map.data
        for index, subindex, start, stop, var in self._layouts[id(pdo_map)]:
            data = frame[start:stop] if var is None else var.get_data()
            if store.get(index, {}).get(subindex) == data:
                # an output the PDO carries at the value it has: nothing changes (a stream's
                # PDO carries its other outputs as they are; four physics events became one)
                continue
            self.node.set_data(index, subindex, data)

    @staticmethod
    def _rpdo_layout(
        pdo_map: canopen.pdo.PdoMap,
    ) -> list[tuple[int, int, int, int, canopen.pdo.PdoVariable | None]]:
        """Where each of the PDO's objects lies in its frame, in bytes (the variable itself
        where it is not whole bytes): ``PdoVariable.get_data`` per object per frame was a fifth
        of a streamed set-point's time."""
        layout: list[tuple[int, int, int, int, canopen.pdo.PdoVariable | None]] = []
        for var in pdo_map.map:
            offset = var.offset
            assert offset is not None  # placed by the map's read
            start, stop = offset // 8, (offset + var.length) // 8
            whole = offset % 8 == 0 and var.length % 8 == 0
            layout.append((var.index, var.subindex, start, stop, None if whole else var))
        return layout

    def _on_nmt(self, can_id: int, data: bytearray, timestamp: float) -> None:
        # the new state's heartbeat goes out at once (``_produce``): LocalNode's NMT slave
        # subscribed first, has switched and said so
        if len(data) == 2 and data[0] == cf.NMT_START and data[1] in (0, self.node_id):
            self.latched = False  # back to work: outputs stay as they are

    # ------------------------------------------------------------------ heartbeat producer
    def _start_heartbeat(self, heartbeat_time_ms: int) -> None:
        """0x1017 written, or the boot to pre-operational: a heartbeat now, then every period."""
        self._heartbeat_s = heartbeat_time_ms / 1000.0
        self._heartbeat_due.set()

    def _stop_heartbeat(self) -> None:
        self._heartbeat_s = 0.0
        self._heartbeat_due.set()

    def _produce(self) -> None:
        """Every heartbeat from this one thread, built with the state of the moment it is sent:
        a change of state wakes it, so the host hears the states in the order they were."""
        while True:
            self._heartbeat_due.wait(self._heartbeat_s or None)
            self._heartbeat_due.clear()  # before the state is read: a later change sends again
            if self._stop.is_set():
                return
            if self._heartbeat_s > 0:
                state = NMT_CODES.get(self.node.nmt.state)
                if state:  # 0, initialising: the NMT slave itself sent the boot-up frame
                    self.network.send_message(0x700 + self.node_id, bytes([state]))

    def _on_host_heartbeat(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if self._connected and len(data) == 1:
            self._last_host = self._mono()  # the first one arms the consumer

    # ------------------------------------------------------------------ watchdog and faults
    def _consumer_s(self) -> float:
        entry = self.get(0x1016, 1)
        return (entry & 0xFFFF) / 1000.0

    def _watch(self) -> None:
        while not self._stop.wait(0.05):
            last, period = self._last_host, self._consumer_s()
            if last is not None and period and self._mono() - last > period:
                self._last_host = None  # disarmed until the host is heard again
                if not self.latched:
                    log.warning(
                        "simulated CANopen node %s: host heartbeat lost, error values", self.name
                    )
                    self.go_error(cf.EMCY_HEARTBEAT, emcy=self._connected)

    def go_error(self, code: int, emcy: bool = True) -> None:
        """Outputs to their error values, error register, EMCY ``code``, pre-operational."""
        self.error_outputs()
        self.latched = True
        cast(Any, self.node.sdo)[0x1001].raw = 0x11
        if emcy:
            self.node.emcy.send(code, 0x11)
        if self._connected:
            self.node.nmt.state = "PRE-OPERATIONAL"

    def inject(self, fault: str, code: int, delay_s: float) -> None:
        if fault == "stall":
            self.stalled = True
        elif fault == "busy":
            self.reply_delay_s = float(delay_s)
        elif fault == "disconnect":
            self.connected = False
        elif fault == "bad_response":
            self.bad_response += 1
        elif fault == "reset":
            self.latched = False
            self.power_on()
        elif fault == "error":
            self.go_error(code)

    def close(self) -> None:
        """Stop the node's threads (the shared network is closed by its owner)."""
        self._stop.set()
        for timer in self._timers:
            timer.cancel()
            timer.join(timeout=1.0)
        self._heartbeat_due.set()
        self._thread.join(timeout=1.0)
        self._producer.join(timeout=1.0)


class CanopenDacNode(CanopenSimNode):
    """A CiA 401 analogue-output module: 16-bit counts over +-10 V (``drivers/eds/<name>.eds``)."""

    outputs: tuple[str, ...] = ()

    @property
    def values(self) -> dict[str, int]:
        """Each output in microvolts."""
        return {out: round(self.counts(i + 1) * LSB_V * 1e6) for i, out in enumerate(self.outputs)}

    def counts(self, sub: int) -> int:
        return self.get(AO_16, sub)

    def reset_outputs(self) -> None:
        for out in self.outputs:
            self._apply(out, 0.0)

    def error_outputs(self) -> None:
        for sub in range(1, len(self.outputs) + 1):
            if self.get(AO_ERROR_MODE, sub) == 1:
                self.set(AO_16, sub, self.get(AO_ERROR_VALUE, sub))

    def go_safe(self) -> None:
        for sub in range(1, len(self.outputs) + 1):
            self.set(AO_16, sub, 0)

    def _on_write(
        self, index: int, subindex: int, od: canopen.objectdictionary.ODVariable, data: bytes
    ) -> None:
        value = od.decode_raw(data)
        if index == AO_ERROR_MODE and value not in (0, 1):
            raise SdoAbortedError(ABORT_VALUE_RANGE)
        if index == AO_16 and 1 <= subindex <= len(self.outputs):
            assert isinstance(value, int)
            self._apply(self.outputs[subindex - 1], value * LSB_V)

    def _apply(self, output: str, volts: float) -> None:
        raise NotImplementedError


class CanopenCagingNode(CanopenSimNode):
    """The caging-inhibit switches as a CiA 401 digital-output module: 0x6200 sub 1, bit 0 X,
    1 Y, 2 Z, 3 XRD (1 = inhibited), bits 4-7 refused (``drivers/eds/caging.eds``)."""

    name = "caging"
    channels = GYRO_CHANNELS

    @property
    def inhibit(self) -> dict[str, bool]:
        """Each switch, True inhibited."""
        word = self.get(DO_8, 1)
        return {c: bool(word >> i & 1) for i, c in enumerate(self.channels)}

    def reset_outputs(self) -> None:
        self._apply(0)

    def error_outputs(self) -> None:
        mask, value = self.get(DO_ERROR_MODE, 1), self.get(DO_ERROR_VALUE, 1)
        self.set(DO_8, 1, (self.get(DO_8, 1) & ~mask) | (value & mask))

    def go_safe(self) -> None:
        self.set(DO_8, 1, 0)

    def _on_write(
        self, index: int, subindex: int, od: canopen.objectdictionary.ODVariable, data: bytes
    ) -> None:
        value = od.decode_raw(data)
        assert isinstance(value, int)
        if index == DO_8 and subindex == 1:
            if value & ~0x0F:
                raise SdoAbortedError(ABORT_VALUE_RANGE)  # outputs 5-8 are not wired
            self._apply(value)

    def _apply(self, word: int) -> None:
        def apply(sim) -> None:
            for i, c in enumerate(self.channels):
                sim.set_caging_inhibit(c, bool(word >> i & 1))

        self.server.submit(apply)


class CanopenRelayNode(CanopenSimNode):
    """The relay driver: the mode register, hold/select/release, the interlocks of modes 4
    and 5, the alarm and the platform clamp (docs/protocol.md 2.5, 2.5a) behind manufacturer
    objects 0x2000-0x2006 (``drivers/eds/relay.eds``). Refusals are SDO aborts: 0x08000020 an
    interlock (reasons in 0x2003), 0x08000021 not held, 0x08000022 not operational."""

    name = "relay"

    def reset_outputs(self) -> None:
        if not getattr(self, "_attached", False):
            # the rig may have been running for hours: the register holds the mode in force, the
            # clamp (a mechanism) is where it was left
            self._attached = True
            self.mode = self.selected = self.server.sim.mode
            self.clamped = self.server.sim.clamped
            self.held = self.alarm = False
            self.reasons = 0
        else:
            self.go_safe()

    def error_outputs(self) -> None:
        self.go_safe()

    def go_safe(self) -> None:
        # mode 1 is allowed clamped or not: the safe state never moves the clamp
        self.mode = self.selected = 1
        self.held = self.alarm = False
        self.server.submit(lambda sim: sim.set_mode(1))

    def _commands_zero(self) -> bool:
        """The node senses the command DAC outputs (V_Td, gamma_c) on its interlock lines."""
        command = self.server.nodes.nodes["command"]
        return not any(cast(Any, command).values.values())  # a CanopenCommandNode

    def status_word(self) -> int:
        snap = self.server.snapshot
        w = (self.mode << rn.ST_MODE_SHIFT) | (self.selected << rn.ST_SELECT_SHIFT)
        w |= (rn.ST_HELD if self.held else 0) | (rn.ST_ALARM if self.alarm else 0)
        w |= rn.ST_CLAMPED if self.clamped else 0
        for i, c in enumerate(GYRO_CHANNELS):
            w |= int(snap.at_speed) << (rn.ST_AT_SPEED_SHIFT + i)
            w |= int(snap.caged[c]) << (rn.ST_CAGED_SHIFT + i)
        return w | (min(100, int(snap.spin * 100)) << rn.ST_SPIN_SHIFT)

    def _on_read(
        self, index: int, subindex: int, od: canopen.objectdictionary.ODVariable
    ) -> int | None:
        return {
            R_MODE: lambda: self.mode,
            R_SELECTED: lambda: self.selected,
            R_REASONS: lambda: self.reasons,
            R_STATUS: self.status_word,
            R_CLAMP: lambda: int(self.clamped),
        }.get(index, lambda: None)()

    def _on_write(
        self, index: int, subindex: int, od: canopen.objectdictionary.ODVariable, data: bytes
    ) -> None:
        if index not in (R_SWITCHES, R_SELECTED, R_CLAMP, R_SAFE):
            return
        value = od.decode_raw(data)
        assert isinstance(value, int)
        if index == R_SAFE:
            if value != 1:
                raise SdoAbortedError(ABORT_VALUE_RANGE)
            self.go_safe()
            return
        if self.node.nmt.state != "OPERATIONAL":
            raise SdoAbortedError(ABORT_NOT_OPERATIONAL)
        if index == R_SWITCHES:
            if value == 1:
                self.held, self.selected = True, self.mode
            elif value == 2:
                self._release()
            else:
                raise SdoAbortedError(ABORT_VALUE_RANGE)
        elif index == R_SELECTED:
            if not self.held:
                raise SdoAbortedError(ABORT_NOT_HELD)
            if not 1 <= value <= 6:
                self.alarm = True  # the register is not clocked; the lamp lights
                raise SdoAbortedError(ABORT_VALUE_RANGE)
            self.selected, self.alarm = value, False
        else:
            self._clamp(value)

    def _refuse(self, why: int) -> None:
        self.reasons = why
        raise SdoAbortedError(ABORT_INTERLOCK)

    def _release(self) -> None:
        if not self.held:
            raise SdoAbortedError(ABORT_NOT_HELD)
        self.held = False
        m = self.selected
        if self.clamped and m not in rn.CLAMP_MODES:
            self.selected = self.mode
            self._refuse(rn.WHY_CLAMPED)
        if m in (4, 5):
            snap = self.server.snapshot
            need = ("X", "Y", "Z", "XRD") if m == 4 else ("X", "Y", "XRD")
            why = (0 if snap.at_speed else rn.WHY_NOT_AT_SPEED) | (
                0 if all(snap.caged[c] for c in need) else rn.WHY_NOT_CAGED
            )
            if why:
                self.selected = self.mode
                self._refuse(why)
        if m != self.mode:
            self.mode = m
            self.server.submit(lambda sim: sim.set_mode(m))

    def _clamp(self, value: int) -> None:
        if value not in (0, 1):
            raise SdoAbortedError(ABORT_VALUE_RANGE)
        on = bool(value)
        if on == self.clamped:
            return
        why = 0 if self._commands_zero() else rn.WHY_COMMAND
        if on and (
            self.mode not in rn.CLAMP_MODES or (self.held and self.selected not in rn.CLAMP_MODES)
        ):
            why |= rn.WHY_MODE
        if why:
            self._refuse(why)
        self.clamped = on
        self.server.submit(lambda sim: sim.set_clamp(on))


class CanopenTableNode(CanopenSimNode):
    """A motorized rotary table behind manufacturer objects 0x2200-0x2204 (micro-degrees;
    ``drivers/eds/table.eds``); it reaches the commanded angle at the next block."""

    name = "table"

    def reset_outputs(self) -> None:
        t = self.server.sim.cfg.table  # at power-on the table reports where it is
        self.tilt, self.spindle = rn.to_micro(t.tilt_deg), rn.to_micro(t.spindle_deg % 360.0)

    def error_outputs(self) -> None:
        pass  # a table at rest is safe where it is

    def go_safe(self) -> None:
        pass

    def _on_read(
        self, index: int, subindex: int, od: canopen.objectdictionary.ODVariable
    ) -> int | None:
        return {
            T_TILT: self.tilt,
            T_SPINDLE: self.spindle,
            T_ACTUAL_TILT: self.tilt,
            T_ACTUAL_SPINDLE: self.spindle,
            T_MOVING: 0,
        }.get(index)

    def _on_write(
        self, index: int, subindex: int, od: canopen.objectdictionary.ODVariable, data: bytes
    ) -> None:
        value = od.decode_raw(data)
        assert isinstance(value, int)
        if index == T_TILT:
            deg = rn.from_micro(value)
            if not 0.0 <= deg <= 90.0:
                raise SdoAbortedError(ABORT_VALUE_RANGE)
            self.tilt = value
            self.server.submit(lambda sim: sim.set_table(tilt_deg=deg))
        elif index == T_SPINDLE:
            spindle = rn.from_micro(value) % 360.0
            self.spindle = rn.to_micro(spindle)
            self.server.submit(lambda sim: sim.set_table(spindle_deg=spindle))


class CanopenTorquerNode(CanopenDacNode):
    """The four torquer bias DACs (``drivers/eds/torquer.eds``)."""

    name = "torquer"
    outputs = GYRO_CHANNELS

    def _apply(self, output: str, volts: float) -> None:
        self.server.submit(lambda sim: sim.set_torquer_bias_V(output, volts), inline=True)


class CanopenCommandNode(CanopenDacNode):
    """The six command DACs, V_Td and gamma_c per axis (``drivers/eds/command.eds``)."""

    name = "command"
    outputs = tuple(f"vtd_{a}" for a in AXES) + tuple(f"gc_{a}" for a in AXES)

    def _apply(self, output: str, volts: float) -> None:
        kind, axis = output.split("_")
        if kind == "vtd":
            self.server.submit(lambda sim: sim.set_command_torque_V(axis, volts), inline=True)
        else:
            self.server.submit(lambda sim: sim.set_ac_bias_V(axis, volts), inline=True)


#: the simulated nodes that can speak CANopen, by name
CANOPEN_NODE_CLASSES: dict[str, type[CanopenSimNode]] = {
    c.name: c
    for c in (
        CanopenTorquerNode,
        CanopenCommandNode,
        CanopenCagingNode,
        CanopenRelayNode,
        CanopenTableNode,
    )
}
