"""The four caging-inhibit switches (II C.2): open one gyro channel's caging loop."""

from __future__ import annotations

import threading
from typing import Protocol

from drivers import canopen_frames as cf
from drivers.can_link import CanLink
from drivers.canopen_client import CanopenClient
from drivers.errors import ProtocolError, SetpointRangeError
from drivers.rig_datasheet import GYRO_CHANNELS
from drivers.setpoints import check_name


class CagingSwitches(Protocol):
    """The caging-inhibit switches, whatever the wire."""

    channels: tuple[str, ...]

    def set_inhibit(self, channel: str, inhibit: bool) -> bool:
        """Set one switch; returns its read-back."""
        ...

    def inhibited(self, channel: str) -> bool: ...

    def clear(self) -> None: ...


#: CiA 401 digital outputs: write outputs 1-8, error mode and error value of outputs 1-8
DO_8, DO_ERROR_MODE, DO_ERROR_VALUE = 0x6200, 0x6206, 0x6207


class CanopenCagingSwitches:
    """The caging switches on a CiA 401 digital-output node (``drivers/eds/caging.eds``):
    output bit i is channel i's inhibit; on a communication error all four release."""

    channels: tuple[str, ...] = GYRO_CHANNELS

    def __init__(self, link: CanLink) -> None:
        mask = (1 << len(self.channels)) - 1
        self.node = CanopenClient(
            link,
            "caging",
            cf.DEVICE_TYPE_401_DO,
            raw_index=DO_8,
            raw_bits=True,
            safe_values=[((DO_8, 1), 0)],
            configure=[((DO_ERROR_MODE, 1), mask), ((DO_ERROR_VALUE, 1), 0)],
        )
        self._lock = threading.Lock()  # one read-modify-write of the output byte at a time

    def clear(self) -> None:
        for c in self.channels:
            self.set_inhibit(c, False)

    def set_inhibit(self, channel: str, inhibit: bool) -> bool:
        i = self.channels.index(check_name("gyro channel", channel, self.channels))
        if not isinstance(inhibit, bool):
            raise SetpointRangeError(
                f"caging inhibit for {channel} must be True or False, not {inhibit!r}; "
                f"nothing was sent",
                value=inhibit,
            )
        with self._lock:
            word = self.node.read(DO_8, 1, what="read caging outputs")
            want = (word | 1 << i) if inhibit else (word & ~(1 << i))
            self.node.write(DO_8, 1, want, what=f"caging inhibit {channel} = {inhibit}")
            back = self.node.read(DO_8, 1, what="read back caging outputs")
        if back != want:
            fault = ProtocolError(
                f"CAN node 'caging': outputs read back 0x{back:02x} after setting 0x{want:02x} "
                f"(inhibit {channel} = {inhibit})"
            )
            self.node.link.faults.report(fault)
            raise fault
        return bool(back >> i & 1)

    def inhibited(self, channel: str) -> bool:
        i = self.channels.index(check_name("gyro channel", channel, self.channels))
        return bool(self.node.read(DO_8, 1, what=f"read caging inhibit {channel}") >> i & 1)
