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

import time
from collections.abc import Callable, Collection
from typing import TYPE_CHECKING

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
        #: the one network of the simulated nodes (one receiving thread for all of them)
        self.network = canopen.Network()
        # its notifier's receive wait: the package's 1 s would hold up every close by up to that
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
