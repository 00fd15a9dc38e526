"""The four gyro torquer bias DACs (II C.1.a(1)): one bias voltage per gyro channel.

A bias beyond the DAC's range or beyond what torques the gyro at 3.5 x earth rate (with the
nominal torquer scale factor) is refused before anything is sent.
"""

from __future__ import annotations

from typing import Protocol

from drivers import can_protocol as cp
from drivers.calibration import GYRO_CHANNELS, RigCalibration
from drivers.can_link import CanLink, NodeClient
from drivers.errors import ProtocolError
from drivers.setpoints import SetpointLimits, check_name


class TorquerDac(Protocol):
    """The torquer bias DACs, whatever the wire."""

    channels: tuple[str, ...]
    limits: SetpointLimits

    def set_bias_V(self, channel: str, volts: float) -> float:
        """Set one bias (checked against ``limits`` first); returns the DAC's read-back (V)."""
        ...

    def bias_V(self, channel: str) -> float: ...

    def zero(self) -> None: ...


class CanTorquerDac:
    """The torquer DACs on their CAN node."""

    channels: tuple[str, ...] = GYRO_CHANNELS

    def __init__(self, link: CanLink, calibration: RigCalibration | None = None) -> None:
        self.limits = SetpointLimits(calibration or RigCalibration())
        self.node = NodeClient(link, "torquer")

    def set_bias_V(self, channel: str, volts: float) -> float:
        v = self.limits.torquer_bias(channel, volts)
        i = self.channels.index(channel)
        back = cp.from_micro(self.node.call(cp.OP_SET, i, cp.to_micro(v), what=f"torquer bias {v:+.6f} V on {channel}"))
        return check_readback(self.node, f"torquer bias on {channel}", v, back, self.limits.calibration.dac_lsb_V)

    def bias_V(self, channel: str) -> float:
        i = self.channels.index(check_name("gyro channel", channel, self.channels))
        return cp.from_micro(self.node.call(cp.OP_GET, i, what=f"read torquer bias {channel}"))

    def zero(self) -> None:
        for c in self.channels:
            self.set_bias_V(c, 0.0)


def check_readback(node: NodeClient, what: str, sent: float, back: float, lsb: float) -> float:
    """A DAC's read-back must equal the set-point within one LSB; anything else is a fault."""
    if abs(back - sent) > lsb * 1.001 + 1e-6:
        fault = ProtocolError(f"CAN node '{node.name}': {what} reads back {back:+.6f} V after setting "
                              f"{sent:+.6f} V (more than one LSB, {lsb * 1e3:.3f} mV, apart)")
        node.link.faults.report(fault)
        raise fault
    return back
