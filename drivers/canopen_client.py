"""One CANopen node as a device driver sees it: checked SDO reads and writes, typed errors,
and the connect sequence (identify, configure the host-heartbeat watchdog, NMT start).

Every rig node is one (``docs/protocol.md`` section 2, ``docs/canopen-plan.md`` section 2).
The SDO transfers are the ``canopen`` package's, over ``CanLink``'s ``network``; one
transfer at a time per node.
"""

from __future__ import annotations

import logging
import queue
import struct
import threading
from collections.abc import Callable, Sequence

import can
import canopen
from canopen.sdo import SdoClient
from canopen.sdo.constants import (
    ABORT_INVALID_COMMAND_SPECIFIER,
    EXPEDITED,
    REQUEST_DOWNLOAD,
    RESPONSE_ABORTED,
    RESPONSE_DOWNLOAD,
    SDO_STRUCT,
    SIZE_SPECIFIED,
)
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

from drivers import canopen_frames as cf
from drivers.can_link import CanLink
from drivers.errors import (
    DeviceLost,
    DeviceTimeout,
    DriverError,
    InterlockError,
    ProtocolError,
    SetpointRangeError,
)

log = logging.getLogger(__name__)

#: SDO abort codes (CiA 301) the host turns into refusals rather than faults
ABORT_RANGE = (0x06090030, 0x06090031, 0x06090032, 0x06090036)
#: "data cannot be transferred or stored": the relay node's refusals (docs/canopen-plan.md 5):
#: an interlock (reasons in 0x2003), the mode switches not held, the node not operational
ABORT_INTERLOCK, ABORT_NOT_HELD, ABORT_NOT_OPERATIONAL = 0x08000020, 0x08000021, 0x08000022
ABORT_STATE = (ABORT_INTERLOCK, ABORT_NOT_HELD, ABORT_NOT_OPERATIONAL)
ABORT_TEXT = {
    ABORT_INTERLOCK: "interlock",
    ABORT_NOT_HELD: "mode switches not held",
    ABORT_NOT_OPERATIONAL: "node not operational (latched safe: the host's NMT start releases it)",
}
ABORT_NO_OBJECT = 0x06020000

#: one object of a node: (index, subindex)
Address = tuple[int, int]


def device_type_serves(found: int, expected: int) -> bool:
    """Whether a node of device type ``found`` (0x1000) serves where ``expected`` is asked for.
    CiA 301: the low 16 bits are the device profile (401 = 0x0191), the high 16 bits additional
    information; in CiA 401 one bit per kind of I/O (16 digital inputs, 17 digital outputs,
    18 analogue inputs, 19 analogue outputs). The profile must match and every expected bit be
    set: a module with more kinds of I/O than the rig uses serves too."""
    return (found & 0xFFFF) == (expected & 0xFFFF) and found & expected == expected


class DeadlineSdoClient(SdoClient):
    """The ``canopen`` package's SDO client, waiting for an answer on the link's deadline clock
    (``CanLink.monotonic``) instead of the wall's: the sim rig's nodes run in this process, so
    its deadline leaves out the time the host could not run them (``drivers.runclock``)."""

    def __init__(
        self,
        rx_cobid: int,
        tx_cobid: int,
        od: canopen.ObjectDictionary,
        monotonic: Callable[[], float],
    ) -> None:
        super().__init__(rx_cobid, tx_cobid, od)
        self.monotonic = monotonic
        #: the object of the transfer under way (from its initiate request): what an initiate
        #: answer must name, and what an abort frame names (CiA 301 7.2.4.3.17)
        self._object = bytes(3)

    def send_request(self, request: bytes | bytearray) -> None:
        request = bytearray(request)
        if request[0] & 0xE0 in (0x20, 0x40):  # initiate download / upload
            self._object = bytes(request[1:4])
        elif request[0] == 0x80:  # abort: the package leaves 0x0000:00
            request[1:4] = self._object
        super().send_request(request)

    def download(self, index: int, subindex: int, data: bytes, force_segment: bool = False) -> None:
        """The package's download; one of 1-4 bytes as its expedited download makes it (the
        same request frame, the answer checked the same way), without the file-like streams
        it goes through, which were a fifth of the host's share of a set-point's round trip."""
        if force_segment or not 1 <= len(data) <= 4:
            super().download(index, subindex, data, force_segment)
            return
        command = REQUEST_DOWNLOAD | EXPEDITED | SIZE_SPECIFIED | (4 - len(data)) << 2
        request = SDO_STRUCT.pack(command, index, subindex) + bytes(data).ljust(4, b"\x00")
        response = self.request_response(request)
        if response[0] & 0xE0 != RESPONSE_DOWNLOAD:
            self.abort(ABORT_INVALID_COMMAND_SPECIFIER)
            raise SdoCommunicationError(f"Unexpected response 0x{response[0]:02X}")

    def read_response(self) -> bytes:
        deadline = self.monotonic() + self.RESPONSE_TIMEOUT
        while True:
            try:
                response: bytes = self.responses.get(
                    block=True, timeout=min(0.05, self.RESPONSE_TIMEOUT)
                )
                break
            except queue.Empty:
                if self.monotonic() > deadline:
                    raise SdoCommunicationError("No SDO response received") from None
        if response[0] == RESPONSE_ABORTED:
            raise SdoAbortedError(struct.unpack_from("<L", response, 4)[0])
        if response[0] & 0xE0 in (0x40, 0x60) and bytes(response[1:4]) != self._object:
            # an initiate answer for another object (the package checks uploads, not downloads)
            got, want = (int.from_bytes(o[:2], "little") for o in (response[1:4], self._object))
            raise SdoCommunicationError(
                f"the answer names object 0x{got:04x}:{response[3]}, not the "
                f"0x{want:04x}:{self._object[2]} asked"
            )
        return response


class RigRemoteNode(canopen.RemoteNode):
    """A remote node whose SDO clients are ``DeadlineSdoClient`` on ``monotonic``."""

    def __init__(
        self, node_id: int, eds: str | canopen.ObjectDictionary, monotonic: Callable[[], float]
    ) -> None:
        self._monotonic = monotonic  # before the base class adds the default SDO channel
        super().__init__(node_id, eds)

    def add_sdo(self, rx_cobid: int, tx_cobid: int) -> SdoClient:
        client = DeadlineSdoClient(rx_cobid, tx_cobid, self.object_dictionary, self._monotonic)
        self.sdo_channels.append(client)
        if self.has_network():
            self.network.subscribe(client.tx_cobid, client.on_response)
        return client


class CanopenClient:
    """Node ``name`` (one of ``link.ids``) on ``link``, described by its EDS file."""

    def __init__(
        self,
        link: CanLink,
        name: str,
        device_type: int,
        *,
        safe_values: Sequence[tuple[Address, int]] = (),
        raw_index: int = 0,
        raw_bits: bool = False,
        configure: Sequence[tuple[Address, int]] = (),
    ) -> None:
        self.link = link
        self.name = name
        self.node_id = link.ids[name]
        self.device_type = device_type
        #: what ``safe`` writes, in order; ``raw_get(i)`` reads ``(raw_index, i + 1)``, or with
        #: ``raw_bits`` bit i of ``(raw_index, 1)`` (a digital-output block)
        self.safe_values = list(safe_values)
        self.raw_index = raw_index
        self.raw_bits = raw_bits
        #: written at connect (after the heartbeat settings): error modes, error values
        self.configuration = list(configure)
        self.node = RigRemoteNode(
            self.node_id, cf.object_dictionary(name, self.node_id), link.monotonic
        )
        self.node.sdo.RESPONSE_TIMEOUT = link.reply_timeout_s
        self.node.sdo.MAX_RETRIES = 1
        link.network.add_node(self.node)
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ SDO
    def _where(self, index: int, sub: int) -> str:
        return f"CAN node '{self.name}' (id {self.node_id}) object 0x{index:04x}:{sub}"

    def read(self, index: int, sub: int = 0, *, what: str = "", check_faults: bool = True) -> int:
        """Upload one numeric object (its raw integer, typed by the EDS)."""
        what = what or f"read 0x{index:04x}:{sub}"
        raw = self._transfer(index, sub, None, what, check_faults)
        assert raw is not None
        value = self._decode(index, sub, raw, what)
        if not isinstance(value, int):
            raise ProtocolError(f"{self._where(index, sub)} is not an integer object ({value!r})")
        return value

    def read_if_present(self, index: int, sub: int = 0, *, what: str = "") -> int | None:
        """``read``, but None where the node has no such object (a commercial module without a
        manufacturer object): the caller falls back to the EDS."""
        what = what or f"read 0x{index:04x}:{sub}"
        raw = self._transfer(index, sub, None, what, True, missing_ok=True)
        if raw is None:
            return None
        value = self._decode(index, sub, raw, what)
        if not isinstance(value, int):
            raise ProtocolError(f"{self._where(index, sub)} is not an integer object ({value!r})")
        return value

    def _decode(self, index: int, sub: int, raw: bytes, what: str) -> object:
        try:
            return self._variable(index, sub).decode_raw(raw)
        except (canopen.objectdictionary.ObjectDictionaryError, struct.error) as exc:
            raise self._bad_answer(index, sub, what, exc) from None  # a short or long answer

    def write(
        self, index: int, sub: int, value: int, *, what: str = "", check_faults: bool = True
    ) -> None:
        """Download one numeric object; a refusal raises its typed error, a fault latches."""
        var = self._variable(index, sub)
        try:
            data = var.encode_raw(value)
        except (struct.error, OverflowError, ValueError, TypeError) as exc:
            raise SetpointRangeError(
                f"{self._where(index, sub)}: {value!r} does not fit its type "
                f"({exc}); nothing was sent",
                value=value,
            ) from None
        self._transfer(
            index, sub, data, what or f"write 0x{index:04x}:{sub} = {value}", check_faults
        )

    def eds_default(self, index: int, sub: int = 0) -> int:
        """The EDS's default value of an integer object."""
        value = self._variable(index, sub).default
        if not isinstance(value, int):
            raise ProtocolError(f"{self._where(index, sub)} has no integer default in its EDS")
        return value

    def _variable(self, index: int, sub: int) -> canopen.objectdictionary.ODVariable:
        try:
            obj = self.node.object_dictionary[index]
            var = obj if isinstance(obj, canopen.objectdictionary.ODVariable) else obj[sub]
        except KeyError:
            raise ProtocolError(
                f"{self._where(index, sub)} is not in its EDS ({cf.eds_path(self.name).name})"
            ) from None
        assert isinstance(var, canopen.objectdictionary.ODVariable)
        return var

    def _transfer(
        self,
        index: int,
        sub: int,
        data: bytes | None,
        what: str,
        check_faults: bool,
        missing_ok: bool = False,
    ) -> bytes | None:
        if check_faults:
            self.link.faults.check()
        try:
            with self._lock:
                if data is None:
                    return self.node.sdo.upload(index, sub)
                self.node.sdo.download(index, sub, data)
                return data
        except SdoAbortedError as exc:
            if missing_ok and exc.code == ABORT_NO_OBJECT:
                return None
            raise self._refusal(index, sub, what, exc.code) from None
        except (SdoCommunicationError, struct.error) as exc:
            if isinstance(exc, struct.error) or "No SDO response" not in str(exc):
                raise self._bad_answer(index, sub, what, exc) from None
            fault: DriverError = DeviceTimeout(
                f"{self._where(index, sub)}: no SDO answer to {what} within "
                f"{self.link.reply_timeout_s:g} s ({exc}); the rig went safe"
            )
        except (can.CanError, OSError, ValueError) as exc:
            fault = DeviceLost(
                f"CAN {self.link.channel}: cannot send to node '{self.name}' ({exc}); "
                f"is the interface up?"
            )
        self.link.faults.report(fault)
        raise fault

    def _refusal(self, index: int, sub: int, what: str, code: int) -> DriverError:
        text = f"{self._where(index, sub)} refused {what}: {SdoAbortedError(code)}"
        if code in ABORT_RANGE:
            var = self._variable(index, sub)
            return SetpointRangeError(text, limit=(var.min, var.max))
        if code in ABORT_STATE:
            return InterlockError(f"{text} ({ABORT_TEXT[code]})", detail=code)
        fault = ProtocolError(text)
        self.link.faults.report(fault)
        return fault

    # ------------------------------------------------------------------ connect and safe
    def connect(self, deadline: float, window_s: float) -> int:
        """Bring the node up as a CiA 301 master does, before it counts as the rig's: NMT
        "enter pre-operational" (a stopped node answers SDO again), then its device type asked
        until it answers or ``deadline`` (the link's clock) passes: a module at factory
        defaults sends no heartbeat, and one powered up with the PC boots later than the host.
        Then ``identify`` and ``clear`` without its wait. Returns the product code."""
        self.node.nmt.send_command(cf.NMT_ENTER_PRE_OPERATIONAL)
        timeout = self.node.sdo.RESPONSE_TIMEOUT
        try:
            while True:
                left = deadline - self.link.monotonic()
                self.node.sdo.RESPONSE_TIMEOUT = max(0.05, min(timeout, left))
                try:
                    with self._lock:
                        self.node.sdo.upload(0x1000, 0)
                    break
                except SdoCommunicationError as exc:
                    if "No SDO response" not in str(exc):
                        raise self._bad_answer(0x1000, 0, "read device type", exc) from None
                    if self.link.monotonic() >= deadline:
                        raise DeviceLost(
                            f"CAN node '{self.name}' (id {self.node_id}) did not answer within the "
                            f"connect window of {window_s:g} s (rig URL connect_s=S); check its "
                            f"power, its cable and termination, and that its node id is "
                            f"{self.node_id}"
                        ) from None
                except SdoAbortedError:
                    break  # it answers: ``identify`` says what
        finally:
            self.node.sdo.RESPONSE_TIMEOUT = timeout
        product = self.identify()
        self.clear(wait=False)
        return product

    def _bad_answer(self, index: int, sub: int, what: str, exc: Exception) -> ProtocolError:
        fault = ProtocolError(f"{self._where(index, sub)}: bad SDO answer to {what} ({exc})")
        self.link.faults.report(fault)
        return fault

    def identify(self) -> int:
        """Check the node's device type (0x1000); returns its product code (0x1018:2)."""
        kind = self.read(0x1000, 0, what="read device type", check_faults=False)
        if not device_type_serves(kind, self.device_type):
            raise ProtocolError(
                f"CAN node id {self.node_id} has device type 0x{kind:08x}, expected "
                f"0x{self.device_type:08x} for '{self.name}'; check the node ids and its EDS"
            )
        product = self.read(0x1018, 2, what="read product code", check_faults=False)
        log.info(
            "CAN node '%s' (id %d): device type 0x%08x, product code 0x%08x",
            self.name,
            self.node_id,
            kind,
            product,
        )
        return product

    def clear(self, wait: bool = True) -> None:
        """Configure the node's watchdog on the host heartbeat and its error values, NMT start
        it and (``wait``) wait for its heartbeat to say operational: from then on it counts as
        up, so a reboot is caught. Without ``wait`` the caller waits (``CanLink.wait_operational``),
        for several nodes at once."""
        ms = max(1, round(self.link.node_timeout_s * 1000))
        settings = [
            ((0x1016, 1), (cf.HOST_NODE_ID << 16) | min(ms, 0xFFFF), "host heartbeat consumer"),
            ((0x1017, 0), max(1, round(self.link.heartbeat_period_s * 1000)), "heartbeat period"),
            # CiA 301 error behaviour: a communication error takes it to pre-operational
            # (2 would stop it, and a stopped module never opens again until power-cycled)
            ((0x1029, 1), 0, "error behaviour"),
        ]
        for (index, sub), value, what in settings:
            if index == 0x1029 and self.read_if_present(index, sub, what=f"read {what}") is None:
                continue  # a module without it: pre-operational is CiA 301's default
            self.write(index, sub, value, what=f"set {what}", check_faults=False)
            back = self.read(index, sub, what=f"read back {what}", check_faults=False)
            if back != value:
                raise ProtocolError(
                    f"{self._where(index, sub)} ({what}) reads back 0x{back:x} after 0x{value:x} "
                    f"was written; the module does not keep it"
                )
        self.link.watch(self.name)
        for (index, sub), value in self.configuration:
            self.write(index, sub, value, check_faults=False)
        self.node.nmt.send_command(cf.NMT_START)
        self.link.started(self.name)
        if wait:
            self.link.wait_operational([self.name], self.link.reply_timeout_s)

    def safe(self) -> None:
        for (index, sub), value in self.safe_values:
            self.write(index, sub, value, what="safe value", check_faults=False)

    def raw_get(self, index: int) -> int:
        """Output ``index`` (0-based) as the node has it, while a fault is latched too."""
        if self.raw_bits:
            return (
                self.read(self.raw_index, 1, what="read outputs 1-8", check_faults=False) >> index
                & 1
            )
        if isinstance(
            self.node.object_dictionary[self.raw_index], canopen.objectdictionary.ODVariable
        ):
            return self.read(self.raw_index, 0, what="read its state", check_faults=False)
        return self.read(
            self.raw_index, index + 1, what=f"read output {index + 1}", check_faults=False
        )
