"""The four gyro torquer bias DACs (II C.1.a(1)): one bias voltage per gyro channel.

A bias beyond the DAC's range or beyond what torques the gyro at 3.5 x earth rate (with the
nominal torquer scale factor) is refused before anything is sent.
"""

from __future__ import annotations

from typing import Protocol

from drivers.calibration import GYRO_CHANNELS, RigCalibration
from drivers.can_dac import CanDac
from drivers.can_link import CanLink
from drivers.setpoints import SetpointLimits, check_name


class TorquerDac(Protocol):
    """The torquer bias DACs, whatever the wire."""

    channels: tuple[str, ...]
    limits: SetpointLimits

    def set_bias_V(self, channel: str, volts: float) -> float:
        """Set one bias (checked against ``limits`` first); returns the DAC's read-back (V)."""
        ...

    def bias_V(self, channel: str) -> float:
        """The bias on ``channel`` as the node reads it back (V)."""
        ...

    def zero(self) -> None:
        """Every bias to 0 V (part of the safe state)."""
        ...


class CanTorquerDac(CanDac):
    """The torquer DACs on their CAN node."""

    channels: tuple[str, ...] = GYRO_CHANNELS

    def __init__(self, link: CanLink, calibration: RigCalibration | None = None) -> None:
        super().__init__(link, "torquer", calibration)

    def set_bias_V(self, channel: str, volts: float) -> float:
        v = self.limits.torquer_bias(channel, volts)
        return self.write(self.channels.index(channel), v, f"torquer bias on {channel}")

    def bias_V(self, channel: str) -> float:
        return self.read(self.channels.index(check_name("gyro channel", channel, self.channels)),
                         f"torquer bias {channel}")

    def zero(self) -> None:
        for c in self.channels:
            self.set_bias_V(c, 0.0)
