"""The four gyro torquer bias DACs (II C.1.a(1)): one bias voltage per gyro channel.

A bias beyond the DAC's range or beyond what torques the gyro at 3.5 x earth rate (with the
nominal torquer scale factor) is refused before anything is sent.
"""

from __future__ import annotations

from typing import Protocol

from drivers.can_link import CanLink
from drivers.canopen_dac import CanopenDac
from drivers.rig_datasheet import GYRO_CHANNELS, RigCalibration
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


class CanopenTorquerDac(CanopenDac):
    """The torquer DACs on a CiA 401 analogue-output node (``drivers/eds/torquer.eds``),
    outputs 1-4 the channels X, Y, Z, XRD."""

    channels: tuple[str, ...] = GYRO_CHANNELS

    def __init__(self, link: CanLink, calibration: RigCalibration | None = None) -> None:
        super().__init__(link, "torquer", len(GYRO_CHANNELS), calibration)

    def set_bias_V(self, channel: str, volts: float) -> float:
        v = self.limits.torquer_bias(channel, volts)
        return self.write(self.channels.index(channel), v, f"torquer bias on {channel}")

    def bias_V(self, channel: str) -> float:
        return self.read(
            self.channels.index(check_name("gyro channel", channel, self.channels)),
            f"torquer bias {channel}",
        )

    def zero(self) -> None:
        for c in self.channels:
            self.set_bias_V(c, 0.0)

    def stream_bias_V(self, channel: str, volts: float) -> float:
        """One step of a bias slew by receive PDO (checked against ``limits`` first, nothing
        sent otherwise); unconfirmed: ``confirm`` reads every streamed bias back."""
        v = self.limits.torquer_bias(channel, volts)
        return self.stream(self.channels.index(channel), v, f"torquer bias on {channel}")
