"""The rig: every device driver in one object, its clock, its faults, and the safe state.

``open_rig(url)`` connects to a rig (DESIGN.md section 2)::

    sim                                  the loopback rig, virtual time, cold (mode 1, wheels stopped)
    sim?realtime=1&seed=3&warm=1         paced to the wall clock; started in mode 3, caged
    sim?config=F.toml&table=manual       a sim config; a hand-cranked table (the operator is asked)
    serial:///dev/ttyACM0?can=socketcan:can0[&baud=2000000][&table=manual|can][&connect_s=2]
    serial:///dev/ttyACM0?can=slcan:/dev/ttyUSB0&bitrate=500000&can_tty_baudrate=115200
    sim?can=virtual:NAME&external=torquer
                                         the sim on virtual channel NAME, its torquer left to a
                                         CANopen node the caller runs (tests: acceptance A of issue 21)

A serial rig is claimed before any byte goes to it (``drivers.claim``: one host per rig); its
nodes have ``connect_s`` seconds (default 2) to answer at connect (``docs/protocol.md`` 2.8).
Every CAN node is a CANopen device (``docs/protocol.md`` section 2). ``bitrate`` and every
``can_<option>`` go to ``can.Bus``. python-can's ``virtual`` bus exists only inside one process:
a device in another process needs ``udp_multicast``, ``slcan`` on a pty pair, or ``socketcan`` on
a ``vcan`` interface (``docs/protocol.md`` 2.1).

``serial`` is built in. Other schemes are found by name in the ``fbs.rig_schemes`` entry-point
group (``pyproject.toml``): ``sim`` is ``simhw.rig_scheme:open_sim_rig``, which serves the same
drivers from simulated devices. So the drivers never import the simulator, and a new kind of
rig is a package with an entry point, not an edit here.

Faults that happen off the caller's thread (a node falls silent, the ADC port vanishes) are
latched (``rig.faults``); the rig goes to the safe state at once, and every later call
raises the fault. Refusals (``SetpointRangeError``, ``InterlockError``) change nothing, so
they do not move the rig. ``close`` always leaves the rig safe.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from importlib.metadata import entry_points
from typing import Any
from urllib.parse import parse_qsl, quote, urlsplit

import can

from drivers.adc import Adc
from drivers.caging import CagingSwitches, CanopenCagingSwitches
from drivers.can_link import CanLink
from drivers.canopen_client import CanopenClient
from drivers.claim import RigClaim
from drivers.clock import RigClock, WallClock
from drivers.command import CanopenCommandDac, CommandDac
from drivers.devices import catalogue as device_catalogue
from drivers.errors import DeviceLost, DeviceTimeout, DriverError
from drivers.faults import FaultLatch
from drivers.relay import SAFE_MODE, CanopenRelayDriver, RelayDriver
from drivers.rig_datasheet import RigCalibration
from drivers.serial_adc import ADC_REPLY_TIMEOUT_S, ADC_STALL_TIMEOUT_S, QUIET_S, SerialAdc
from drivers.supervision import ModeSupervisor, SupervisedAdc
from drivers.table import (
    CanopenTable,
    ManualTable,
    Operator,
    RotaryTable,
    TablePosition,
    terminal_operator,
)
from drivers.torquer import CanopenTorquerDac, TorquerDac

log = logging.getLogger(__name__)

#: a set-point stream's reads (``Rig._stream``): about this much rig time at a time. Each read
#: is a block request to the ADC and, on the sim rig, one physics block: at 0.1 s the requests
#: were half a hysteresis sweep's host time. An abort is seen between reads, so on hardware
#: this is also the stream's abort latency; the recorded samples do not depend on it.
STREAM_READ_S = 0.5

#: An event listener gets (rig time s, kind, text); the recorder writes them to /events.
EventListener = Callable[[float, str, str], None]


@dataclass
class SafeReport:
    """What going safe achieved; ``ok`` only if every step was done and read back."""

    done: list[str] = field(default_factory=list)
    failed: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.failed


class Rig:
    def __init__(
        self,
        *,
        url: str,
        adc: Adc,
        relays: RelayDriver,
        torquers: TorquerDac,
        commands: CommandDac,
        caging: CagingSwitches,
        table: RotaryTable,
        clock: RigClock,
        faults: FaultLatch,
        link: CanLink | None = None,
        safe_nodes: Sequence[CanopenClient] = (),
        closers: Sequence[Callable[[], None]] = (),
        emulator: Any = None,
        simulated: bool = False,
        sim_config: Mapping[str, str] | None = None,
        devices: Mapping[str, Any] | None = None,
    ) -> None:
        self.url = url
        #: what the rig states about itself, for every result's provenance: a simulated rig
        #: says so (its scheme sets it), never guessed from the URL's text; its config file
        #: as {"path", "sha256"} (None: the built-in one, or hardware)
        self.simulated = simulated
        self.sim_config = dict(sim_config) if sim_config is not None else None
        #: the rig's data sheet (instrument constants, set-point limits)
        self.calibration = torquers.limits.calibration
        #: watches the gyro modes while they are in force (every block read passes it)
        self.supervisor = ModeSupervisor(self.calibration, faults)
        relays.mode_seen = self._mode_seen
        self.adc: Adc = SupervisedAdc(adc, self.supervisor)
        self.relays, self.torquers, self.commands = relays, torquers, commands
        self.caging, self.table, self.clock, self.faults = caging, table, clock, faults
        #: the drivers of the rig's extra CAN devices (``drivers.devices``), by name
        self.devices: dict[str, Any] = dict(devices or {})
        #: the simulated rig's server, for fault injection in tests; None on hardware
        self.emulator = emulator
        self.link = link
        self._safe_nodes = list(safe_nodes)
        self._closers = list(closers)
        self._listeners: list[EventListener] = []
        self._safe_lock = threading.Lock()
        self._safe_thread: threading.Thread | None = None
        self.closed = False
        faults.on_fault(self._on_fault)

    # ------------------------------------------------------------------ events
    def subscribe(self, listener: EventListener) -> None:
        self._listeners.append(listener)

    def unsubscribe(self, listener: EventListener) -> None:
        if listener in self._listeners:
            self._listeners.remove(listener)

    def event(self, kind: str, text: str) -> None:
        t = self.clock.now()
        # set-points can come a hundred a second (a swept bias): debug, the rest info
        log.log(
            logging.DEBUG if kind == "setpoint" else logging.INFO,
            "rig event at %.3f s: %s: %s",
            t,
            kind,
            text,
        )
        for fn in list(self._listeners):
            try:
                fn(t, kind, text)
            except Exception:  # a listener's trouble is not the rig's
                log.exception("event listener failed")

    # ------------------------------------------------------------------ commands with events
    def set_mode(self, mode: int) -> int:
        try:
            now = self.relays.set_mode(mode)
        except DriverError as exc:
            self.event("alarm", str(exc))
            raise
        self.event("mode", f"mode {now}")
        return now

    def commands_zero(self) -> bool:
        """Every command input (V_Td, gamma_c) reads back 0 V from its DAC."""
        return all(
            self.commands.command_torque_V(a) == 0.0 and self.commands.ac_bias_V(a) == 0.0
            for a in self.commands.axes
        )

    def clamp(self) -> bool:
        """Clamp the platform to the table, motor drive open (Ch. V B; ``RelayDriver.clamp``)."""
        try:
            back = self.relays.clamp(commands_zero=self.commands_zero())
        except DriverError as exc:
            self.event("alarm", str(exc))
            raise
        self.event("clamp", "platform clamped, loops open")
        return back

    def unclamp(self) -> bool:
        """Release the clamp: the stabilization loops take the platform again."""
        try:
            was = self.relays.status().clamped
            self.relays.unclamp(commands_zero=self.commands_zero())
        except DriverError as exc:
            self.event("alarm", str(exc))
            raise
        if was:
            self.event("clamp", "platform released, loops closed")
        return False

    def set_torquer_bias_V(self, channel: str, volts: float) -> float:
        back = self.torquers.set_bias_V(channel, volts)
        self.event("setpoint", f"torquer bias {channel} = {back:+.6f} V")
        return back

    def set_command_torque_V(self, axis: str, volts: float) -> float:
        back = self.commands.set_command_torque_V(axis, volts)
        self.event("setpoint", f"command torque V_Td {axis} = {back:+.6f} V")
        return back

    def stream_command_torque_V(
        self,
        axis: str,
        values_V: Iterable[float],
        period_s: float,
        acquire: Callable[[float], object],
    ) -> int:
        """V_Td on ``axis`` through ``values_V``, one every ``period_s`` of rig time, the
        caller's ``acquire(seconds)`` taking the samples as they go (``_stream``): every value
        checked before it is sent by the node's receive PDO, every streamed output read back at
        the end (``confirm``; ``cmd_<axis>`` records what the platform got all along), one event
        for the whole stream rather than one per set-point.
        V_Td is set to 0 V afterwards, however the stream ends. Returns how many set-points
        were sent."""
        return self._stream(
            f"command torque V_Td {axis}",
            partial(self.commands.put_command_torque_V, axis),
            partial(self.commands.set_command_torque_V, axis),
            values_V,
            period_s,
            acquire,
        )

    def stream_ac_bias_V(
        self,
        axis: str,
        values_V: Iterable[float],
        period_s: float,
        acquire: Callable[[float], object],
    ) -> int:
        """gamma_c on ``axis`` through ``values_V``, as ``stream_command_torque_V`` does V_Td
        (a receive PDO per set-point instead of ``set_ac_bias_V``'s SDO download and read-back;
        read back at the end; one event); 0 V afterwards, however the stream ends.
        Returns how many set-points were sent."""
        return self._stream(
            f"autocollimator bias gamma_c {axis}",
            partial(self.commands.put_ac_bias_V, axis),
            partial(self.commands.set_ac_bias_V, axis),
            values_V,
            period_s,
            acquire,
        )

    def _stream(
        self,
        what: str,
        put: Callable[[float], float],
        set_: Callable[[float], float],
        values_V: Iterable[float],
        period_s: float,
        acquire: Callable[[float], object],
    ) -> int:
        """Set-point k at rig time t0 + k ``period_s`` (``RigClock.at``: hardware waits for it;
        the sim rig's virtual clock schedules it and simulates the stream in blocks, one
        physics block per read rather than per set-point), the samples taken ``STREAM_READ_S``
        at a time, and the rest when the stream ends: in all ``period_s`` per set-point sent."""
        if not (0 < period_s < float("inf")):
            raise ValueError(f"{what}: set-point period {period_s!r} s must be a number > 0")
        per_read = max(1, int(STREAM_READ_S / period_s + 1e-9))
        t0 = self.clock.horizon()
        n = owed = 0
        try:
            for v in values_V:
                self.clock.at(t0 + n * period_s)
                put(float(v))
                n += 1
                owed += 1
                if owed == per_read:
                    acquire(owed * period_s)
                    owed = 0
            if owed:
                acquire(owed * period_s)
            self.commands.confirm()
        finally:
            back = set_(0.0)
            self.event("setpoint", f"{what}: {n} set-points streamed, then {back:+.6f} V")
        return n

    def set_ac_bias_V(self, axis: str, volts: float) -> float:
        back = self.commands.set_ac_bias_V(axis, volts)
        self.event("setpoint", f"autocollimator bias gamma_c {axis} = {back:+.6f} V")
        return back

    def set_caging_inhibit(self, channel: str, inhibit: bool) -> bool:
        back = self.caging.set_inhibit(channel, inhibit)
        self.event("setpoint", f"caging inhibit {channel} = {'on' if back else 'off'}")
        return back

    def move_table(
        self, tilt_deg: float | None = None, spindle_deg: float | None = None
    ) -> TablePosition:
        pos = self.table.move_to(tilt_deg, spindle_deg)
        self.event("table", f"table tilt {pos.tilt_deg:.4f} deg, spindle {pos.spindle_deg:.4f} deg")
        return pos

    # ------------------------------------------------------------------ time
    def now(self) -> float:
        return self.clock.now()

    def wait(self, seconds: float) -> None:
        self.faults.check()
        self.clock.sleep(seconds)
        self.faults.check()

    def wait_until(
        self,
        predicate: Callable[[], bool],
        timeout_s: float,
        poll_s: float = 0.5,
        what: str = "condition",
    ) -> float:
        """Poll ``predicate`` every ``poll_s`` of rig time; returns the rig time it came true."""
        t_end = self.clock.now() + timeout_s
        while not predicate():
            if self.clock.now() >= t_end:
                raise DeviceTimeout(f"{what} not reached within {timeout_s:g} s of rig time")
            self.wait(poll_s)
        return self.clock.now()

    # ------------------------------------------------------------------ safety
    def check(self) -> None:
        self.faults.check()

    def _mode_seen(self, mode: int) -> None:
        self.supervisor.mode = mode

    def _on_fault(self, fault: DriverError) -> None:
        # Runs on whichever thread saw the fault (maybe the CAN receive thread, which the
        # safe-state requests need): go safe on a thread of its own.
        self.event("error", str(fault))
        t = threading.Thread(target=self.safe, name="rig-safe", daemon=True)
        t.start()  # before close() can see it: joining an unstarted thread raises
        self._safe_thread = t

    def safe(self) -> SafeReport:
        """Mode 1, every bias and command zero, caging switches released; each step read back.
        The platform clamp is left where it is: engaging or releasing it is a move the software
        never makes unasked (mode 1 is allowed either way)."""
        with self._safe_lock:
            report = SafeReport()
            for node in self._safe_nodes:
                try:
                    node.safe()
                    report.done.append(f"{node.name} safe")
                except DriverError as exc:
                    report.failed.append(f"{node.name}: {exc}")
            for name, check in (
                ("mode 1", self._mode_is_safe),
                ("biases, commands zero and caging released", self._outputs_zero),
            ):
                try:
                    if check():
                        report.done.append(f"{name} read back")
                    else:
                        report.failed.append(f"{name} not read back")
                except DriverError as exc:
                    report.failed.append(f"{name}: {exc}")
            if report.ok:
                log.info("rig safe: %s", "; ".join(report.done))
            else:
                log.error("rig NOT fully safe: %s", "; ".join(report.failed))
                if self.link is not None and not self.link.heartbeat_suspended:
                    self.link.heartbeat_suspended = True
                    report.failed.append(
                        "host heartbeat stopped: the nodes' watchdogs will make them safe"
                    )
            self.event(
                "safe",
                "safe state reached"
                if report.ok
                else "safe state incomplete: " + "; ".join(report.failed),
            )
            return report

    def _mode_is_safe(self) -> bool:
        mode = self._raw("relay", 0)
        self._mode_seen(mode)
        return mode == SAFE_MODE

    def _outputs_zero(self) -> bool:
        return (
            all(self._raw("torquer", i) == 0 for i in range(4))
            and all(self._raw("command", i) == 0 for i in range(6))
            and all(self._raw("caging", i) == 0 for i in range(4))
        )

    def _raw(self, name: str, index: int) -> int:
        for node in self._safe_nodes:
            if node.name == name:
                return node.raw_get(index)
        raise DriverError(f"no node {name!r} on this rig")

    def is_safe(self) -> bool:
        """Read back mode and outputs (works while a fault is latched)."""
        return self._mode_is_safe() and self._outputs_zero()

    def close(self) -> SafeReport | None:
        if self.closed:
            return None
        self.closed = True
        if self._safe_thread is not None:
            self._safe_thread.join(timeout=10.0)
        report = self.safe()
        for closer in [self.adc.close, *self._closers]:
            try:
                closer()
            except Exception:  # closing must finish even when a device is gone
                log.exception("closing %s failed", closer)
        return report

    def __enter__(self) -> Rig:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# ---------------------------------------------------------------------------- open_rig
_SERIAL_KEYS = {"can", "baud", "table", "bitrate", "connect_s"}
#: how long a serial rig's nodes have to answer at connect (docs/protocol.md 2.8), s
CONNECT_WINDOW_S = 2.0
#: how long a serial rig's host listens for another host's heartbeat before it sends (3 periods), s
LISTEN_S = 0.3
#: URL keys ``can_<option>=<value>`` pass ``<option>`` to ``can.Bus`` (and so does ``bitrate``)
BUS_OPTION_PREFIX = "can_"


def bus_options(url: str, params: Mapping[str, str]) -> dict[str, Any]:
    """python-can bus options from a rig URL: ``bitrate=500000`` and every ``can_<option>=<value>``
    (``can_tty_baudrate=115200`` for slcan, ``can_receive_own_messages=0``); a value is an int, a
    float, a flag (true/false/yes/no/on/off) or else a string."""
    out: dict[str, Any] = {}
    for key, text in params.items():
        if key == "bitrate" or (
            key.startswith(BUS_OPTION_PREFIX) and len(key) > len(BUS_OPTION_PREFIX)
        ):
            option = key if key == "bitrate" else key[len(BUS_OPTION_PREFIX) :]
            out[option] = _option_value(text)
    if "bitrate" in out and (not isinstance(out["bitrate"], int) or out["bitrate"] <= 0):
        raise ValueError(
            f"rig URL {url!r}: bitrate={params['bitrate']!r} must be a positive integer (bit/s)"
        )
    return out


def _option_value(text: str) -> Any:
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    if text.lower() in ("true", "yes", "on", "false", "no", "off"):
        return text.lower() in ("true", "yes", "on")
    return text


#: the entry-point group where rig URL schemes other than ``serial`` are registered
SCHEME_GROUP = "fbs.rig_schemes"

#: opens the rig at a URL of its scheme: (url, its query parameters, operator, data sheet) -> Rig
RigOpener = Callable[[str, dict[str, str], Operator | None, RigCalibration | None], Rig]


def flag(key: str, value: str) -> bool:
    """A URL flag's value: 1/true/yes/on or 0/false/no/off."""
    if value.lower() in ("1", "true", "yes", "on"):
        return True
    if value.lower() in ("0", "false", "no", "off"):
        return False
    raise ValueError(f"rig URL: {key}={value!r} must be 1 or 0")


def open_rig(
    url: str = "sim", *, operator: Operator | None = None, calibration: RigCalibration | None = None
) -> Rig:
    """Connect to the rig at ``url`` (see the module docstring); raises DriverError/ValueError."""
    parts = urlsplit(url)
    params = dict(parse_qsl(parts.query, keep_blank_values=True))
    if parts.scheme == "serial":
        return _open_serial(url, parts.path, params, operator, calibration)
    kind = parts.scheme or parts.path  # "sim?seed=3" has no scheme: its name is the path
    opener = (
        scheme_opener(kind) if kind and (not parts.scheme or parts.path in ("", kind)) else None
    )
    if opener is None:
        raise ValueError(
            f"rig URL {url!r}: unknown rig; use 'sim[?realtime=1&seed=N&warm=1&config=F.toml&table=manual]' "
            f"or 'serial:///dev/ttyACM0?can=socketcan:can0' (schemes: {', '.join(schemes())})"
        )
    return opener(url, params, operator, calibration)


def with_param(url: str, key: str, value: object) -> str:
    """``url`` with ``key=value`` added to its query, the value %-escaped: a path is data, never
    URL text (a file named ``a.toml&warm=1`` must not add ``warm=1``)."""
    return url + ("&" if "?" in url else "?") + f"{key}={quote(str(value), safe='/')}"


def schemes() -> list[str]:
    """The rig URL schemes this installation knows."""
    return sorted({"serial", *(ep.name for ep in entry_points(group=SCHEME_GROUP))})


def scheme_opener(name: str) -> RigOpener | None:
    """The opener registered for the scheme ``name`` (entry-point group ``fbs.rig_schemes``)."""
    for ep in entry_points(group=SCHEME_GROUP, name=name):
        opener: RigOpener = ep.load()
        return opener
    return None


def check_keys(url: str, params: Mapping[str, str], allowed: set[str]) -> None:
    """Refuse a URL parameter the scheme does not know, naming the known ones (``can_<option>``
    bus options are known wherever ``bitrate`` is)."""
    unknown = sorted(
        k
        for k in set(params) - allowed
        if not ("bitrate" in allowed and k.startswith(BUS_OPTION_PREFIX))
    )
    if unknown:
        raise ValueError(
            f"rig URL {url!r}: unknown parameter(s) {', '.join(unknown)} "
            f"(known: {', '.join(sorted(allowed))})"
        )


def _open_serial(
    url: str, path: str, params: dict, operator: Operator | None, calibration: RigCalibration | None
) -> Rig:
    check_keys(url, params, _SERIAL_KEYS)
    if not path:
        raise ValueError(
            f"rig URL {url!r}: no serial device path (e.g. serial:///dev/ttyACM0?can=socketcan:can0)"
        )
    iface, _, channel = params.get("can", "").partition(":")
    if not iface or not channel:
        raise ValueError(
            f"rig URL {url!r}: give the CAN interface as can=<interface>:<channel>, e.g. can=socketcan:can0"
        )
    table = params.get("table", "manual")
    if table not in ("can", "manual"):
        raise ValueError(f"rig URL {url!r}: table={table!r} must be 'can' or 'manual'")
    try:
        baud = int(params.get("baud", "2000000"))
    except ValueError as exc:
        raise ValueError(f"rig URL {url!r}: {exc}") from None
    window = params.get("connect_s", str(CONNECT_WINDOW_S))
    try:
        connect_s = float(window)
    except ValueError:
        connect_s = float("nan")
    if not 0.1 <= connect_s <= 600:  # NaN fails too
        raise ValueError(
            f"rig URL {url!r}: connect_s={window!r} must be a number of seconds in 0.1..600"
        )
    options = bus_options(url, params)
    # One host per rig: the locks before any byte, then the bus heard before it is spoken on
    claim = RigClaim(url, [("adc", path), ("can", f"{iface}:{channel}")])
    try:
        try:
            bus = can.Bus(interface=iface, channel=channel, **options)
        except (can.CanError, OSError, ValueError, ImportError, TypeError) as exc:
            raise DeviceLost(
                f"cannot open CAN interface {iface}:{channel} with {options or 'no options'}: {exc}"
            ) from exc
        tab = (
            ("manual", operator or terminal_operator, TablePosition(0.0, 0.0))
            if table == "manual"
            else ("can",)
        )
        return assemble(
            url,
            path,
            bus,
            f"{iface}:{channel}",
            WallClock(),
            tab,
            calibration,
            baudrate=baud,
            connect_s=connect_s,
            listen_s=LISTEN_S,
            closers=[claim.release],
        )
    except BaseException:
        claim.release()
        raise


def assemble(
    url: str,
    adc_port: str,
    bus: can.BusABC,
    channel: str,
    clock: RigClock,
    table: tuple,
    calibration: RigCalibration | None,
    *,
    baudrate: int = 2_000_000,
    node_timeout_s: float = 1.0,
    reply_timeout_s: float = 0.5,
    closers: list | None = None,
    emulator=None,
    monotonic: Callable[[], float] = time.monotonic,
    connect_s: float = CONNECT_WINDOW_S,
    listen_s: float = 0.0,
    simulated: bool = False,
    sim_config: Mapping[str, str] | None = None,
) -> Rig:
    """The rig from its ADC port and CAN bus. ``monotonic``: the drivers' deadline clock (the
    wall's; the sim rig, whose devices run in this process, gives ``drivers.runclock``'s).
    ``connect_s``: how long the nodes have to answer; ``listen_s``: how long to listen for
    another host first (``CanLink``). ``closers`` run when the rig closes. ``simulated`` and
    ``sim_config``: what the rig states about itself (``Rig.simulated``)."""
    faults = FaultLatch()
    calibration = calibration or RigCalibration()
    devices = device_catalogue()
    names = ["relay", "caging", "torquer", "command"] + (["table"] if table[0] == "can" else [])
    names += list(devices)
    adc = None
    link = None
    try:
        link = CanLink(
            bus,
            names,
            faults=faults,
            channel=channel,
            node_timeout_s=node_timeout_s,
            reply_timeout_s=reply_timeout_s,
            monotonic=monotonic,
            listen_s=listen_s,
        )
        torquers = CanopenTorquerDac(link, calibration)
        commands = CanopenCommandDac(link, calibration)
        caging = CanopenCagingSwitches(link)
        relays = CanopenRelayDriver(link)
        tab: RotaryTable = (
            CanopenTable(link, clock) if table[0] == "can" else ManualTable(table[1], table[2])
        )
        clients: list[CanopenClient] = [relays.node, caging.node, torquers.node, commands.node]
        if isinstance(tab, CanopenTable):
            clients.append(tab.node)
        extra = {name: d.driver(link) for name, d in devices.items()}
        clients += [drv.node for drv in extra.values()]
        # every node brought up within one window: a rig powered up with its PC boots together
        deadline = link.monotonic() + max(connect_s, node_timeout_s)
        for c in clients:
            c.connect(deadline, max(connect_s, node_timeout_s))
        link.wait_operational([c.name for c in clients], max(2.0, reply_timeout_s))
        for dac in (torquers, commands):
            dac.read_scale()
            dac.configure_rpdos()  # a stream must drive the output it is meant for
        # the ADC's own deadlines (2 s for a reply, 3 s of silence while streaming) stretch with a
        # longer CAN reply deadline (the sim rig's 5 s default), never shrink below them; so does
        # the quiet spell that gives up a frame cut short, by as much, leaving a held-back reply
        # the ADC's own 2 s (on the sim rig the device's writer thread shares this process: a
        # busy box held it 0.25 s mid-frame, and a good frame was reported lost)
        adc = SerialAdc(
            adc_port,
            clock=clock,
            faults=faults,
            baudrate=baudrate,
            monotonic=monotonic,
            reply_timeout_s=max(ADC_REPLY_TIMEOUT_S, reply_timeout_s),
            stall_timeout_s=max(ADC_STALL_TIMEOUT_S, reply_timeout_s),
            quiet_s=QUIET_S + max(0.0, reply_timeout_s - ADC_REPLY_TIMEOUT_S),
        )
        rig = Rig(
            url=url,
            adc=adc,
            relays=relays,
            torquers=torquers,
            commands=commands,
            caging=caging,
            table=tab,
            clock=clock,
            faults=faults,
            link=link,
            safe_nodes=[c for c in clients if c.name != "table"],
            closers=[link.close, *(closers or [])],
            emulator=emulator,
            simulated=simulated,
            sim_config=sim_config,
            devices=extra,
        )
    except BaseException:
        if adc is not None:
            adc.close()
        if link is not None:
            link.close()
        raise
    log.info(
        "rig %s open: ADC %s %s on %s; CAN nodes %s on %s",
        url,
        adc.identity.model,
        adc.identity.serial,
        adc_port,
        ", ".join(names),
        channel,
    )
    return rig
