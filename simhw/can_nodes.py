"""The simulated CAN nodes, all on one python-can virtual channel: the device side of
``docs/protocol.md`` section 2. Each node is a CANopen slave (``simhw.canopen_nodes``): it
answers SDO, sends its heartbeat, consumes the host's and, when that stops for longer than
its consumer time, puts its outputs to their error values by itself, says so in an EMCY and
goes pre-operational. Settings reach the physics through ``server.submit``, at the next
block boundary.

``inject`` makes a node misbehave on request: ``stall`` (no SDO answers, heartbeat goes on),
``disconnect`` (silent both ways), ``reset`` (reboot to power-on values), ``error`` (an
EMCY; the node takes its error values and leaves the operational state), ``bad_response``
(the next SDO answer is malformed), ``busy`` (every answer ``delay_s`` late, as from a host
too loaded to schedule the node's thread).
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Collection
from copy import deepcopy
from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

import can
import can.interfaces.virtual
import canopen

from drivers import canopen_frames as cf
from drivers import rig_nodes as rn
from simhw.canopen_nodes import CANOPEN_NODE_CLASSES, NOTIFIER_CYCLE_S, CanopenSimNode
from simhw.devices import catalogue as device_nodes

if TYPE_CHECKING:
    from simhw.rig_server import SimRigServer

NODE_FAULTS = ("stall", "disconnect", "reset", "error", "bad_response", "busy")


class CanNodeHost:
    """Every simulated node of the rig on the virtual channel ``channel`` (the core five and
    each device's, ``simhw.devices``), but the ``external`` ones, which the caller runs there
    itself (a CiA 401 module written in a test)."""

    def __init__(
        self,
        server: SimRigServer,
        channel: str,
        watchdog_s: float = 1.0,
        monotonic: Callable[[], float] = time.monotonic,
        external: Collection[str] = (),
        interface: str = "virtual",
    ) -> None:
        self.channel = channel
        #: every simulated node by name (tests look at their objects)
        self.nodes: dict[str, CanopenSimNode] = {}
        #: the one network of the simulated nodes (on the virtual channel they take each
        #: frame in the sender's thread, ``_deliver_inline``)
        if interface == "virtual":
            bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
            self.network = canopen.Network(bus)
            _deliver_inline(self.network)
        else:
            self.network = canopen.Network()
            # its notifier's receive wait: the package's 1 s would hold up every close by that
            self.network.NOTIFIER_CYCLE = NOTIFIER_CYCLE_S
            self.network.connect(interface=interface, channel=channel, receive_own_messages=False)
        try:
            classes = CANOPEN_NODE_CLASSES | device_nodes()
            for name in rn.node_ids():
                if name in external:
                    continue
                if name not in classes:
                    raise ValueError(
                        f"the device {name!r} (drivers.devices) has no simulated node: "
                        f"simhw/devices/{name}.py defines it"
                    )
                self.nodes[name] = classes[name](server, self.network, watchdog_s, monotonic)
        except BaseException:
            self.close()
            raise

    def inject(
        self, node: str, fault: str, code: int = cf.EMCY_OVERTEMP, delay_s: float = 1.5
    ) -> None:
        if node not in self.nodes:
            raise ValueError(f"unknown node {node!r} (one of {', '.join(self.nodes)})")
        if fault not in NODE_FAULTS:
            raise ValueError(f"unknown node fault {fault!r} (one of {', '.join(NODE_FAULTS)})")
        self.nodes[node].inject(fault, code, delay_s)

    def close(self) -> None:
        for node in self.nodes.values():
            node.close()
        self.network.disconnect()


class _InlineDelivery(queue.Queue[can.Message]):
    """Stands in for the simulated nodes' receive queue on the virtual channel: a frame put
    there is handled at once, in the sending thread, one at a time (``_deliver_inline``);
    nothing is ever queued."""

    def __init__(self, listener: can.Listener) -> None:
        super().__init__()
        self._listener = listener
        self._lock = threading.Lock()

    def put(self, msg: can.Message, block: bool = True, timeout: float | None = None) -> None:
        with self._lock:
            self._listener.on_message_received(msg)

    def deliver(self, msg: can.Message, timestamp: float) -> None:
        """``put`` of a frame the sender still owns: the nodes see its own copy of the bytes
        (``_Frame``), not python-can's copy of the whole message (``InlineVirtualBus``)."""
        self.put(
            cast(
                can.Message,
                _Frame(
                    msg.arbitration_id,
                    bytearray(msg.data),
                    timestamp,
                    msg.is_error_frame,
                    msg.is_remote_frame,
                ),
            )
        )


@dataclass(frozen=True, slots=True)
class _Frame:
    """What a CANopen listener reads of a received frame (``canopen.network.MessageListener``)."""

    arbitration_id: int
    data: bytearray
    timestamp: float
    is_error_frame: bool
    is_remote_frame: bool


class InlineVirtualBus(can.interfaces.virtual.VirtualBus):
    """The host's end of the sim rig's virtual channel: python-can's virtual bus, but a frame
    for the simulated nodes (taken in the sender's thread, ``_InlineDelivery``) reaches them as
    its id, bytes and timestamp, without the deep copy of the whole message python-can makes
    for a queue: that copy was a quarter of a streamed set-point's host time (an excitation
    streams 250 a second). Any other receiver on the channel gets python-can's copy, as ever."""

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        # python-can's VirtualBus.send (4.x), but for the inline receivers
        self._check_if_open()
        timestamp = msg.timestamp if self.preserve_timestamps else time.time()
        all_sent = True
        for bus_queue in self.channel:
            if bus_queue is self.queue and not self.receive_own_messages:
                continue
            if isinstance(bus_queue, _InlineDelivery):
                bus_queue.deliver(msg, timestamp)
                continue
            msg_copy = deepcopy(msg)
            msg_copy.timestamp = timestamp
            msg_copy.channel = self.channel_id
            msg_copy.is_rx = bus_queue is not self.queue
            try:
                bus_queue.put(msg_copy, block=True, timeout=timeout)
            except queue.Full:
                all_sent = False
        if not all_sent:
            raise can.CanOperationError("Could not send message to one or more recipients")


def _deliver_inline(network: canopen.Network) -> None:
    """The simulated nodes take each frame on the virtual channel in the thread that sent it,
    rather than on a receiving thread of their own: the same frames in the same order, a
    thread hand-off fewer per SDO round trip, and a frame the host sends is handled before
    its send returns (as a real bus delivers it while the host goes on)."""
    bus = network.bus
    assert isinstance(bus, can.interfaces.virtual.VirtualBus) and network.notifier is None
    inline = _InlineDelivery(network.listeners[0])
    with can.interfaces.virtual.channels_lock:
        bus.channel[bus.channel.index(bus.queue)] = inline
        bus.queue = inline  # what shutdown takes off the channel
