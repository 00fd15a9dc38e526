"""The four caging-inhibit switches (II C.2): open one gyro channel's caging loop."""

from __future__ import annotations

from typing import Protocol

from drivers import can_protocol as cp
from drivers.calibration import GYRO_CHANNELS
from drivers.can_link import CanLink, NodeClient
from drivers.errors import ProtocolError, SetpointRangeError
from drivers.setpoints import check_name


class CagingSwitches(Protocol):
    """The caging-inhibit switches, whatever the wire."""

    channels: tuple[str, ...]

    def set_inhibit(self, channel: str, inhibit: bool) -> bool:
        """Set one switch; returns its read-back."""
        ...

    def inhibited(self, channel: str) -> bool: ...

    def clear(self) -> None: ...


class CanCagingSwitches:
    """The caging switches on their CAN node."""

    channels: tuple[str, ...] = GYRO_CHANNELS

    def __init__(self, link: CanLink) -> None:
        self.node = NodeClient(link, "caging")

    def clear(self) -> None:
        for c in self.channels:
            self.set_inhibit(c, False)

    def set_inhibit(self, channel: str, inhibit: bool) -> bool:
        i = self.channels.index(check_name("gyro channel", channel, self.channels))
        if not isinstance(inhibit, bool):
            raise SetpointRangeError(f"caging inhibit for {channel} must be True or False, not {inhibit!r}; "
                                     f"nothing was sent", value=inhibit)
        back = bool(self.node.call(cp.OP_SET, i, int(inhibit), what=f"caging inhibit {channel} = {inhibit}"))
        if back != inhibit:
            fault = ProtocolError(f"CAN node 'caging': inhibit {channel} reads back {back} after setting {inhibit}")
            self.node.link.faults.report(fault)
            raise fault
        return back

    def inhibited(self, channel: str) -> bool:
        i = self.channels.index(check_name("gyro channel", channel, self.channels))
        return bool(self.node.call(cp.OP_GET, i, what=f"read caging inhibit {channel}"))
