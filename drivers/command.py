"""The command DACs: platform command torque V_Td and autocollimator bias gamma_c per axis
(Ch. III: V_Td enters the power amplifier through the divider Kd; gamma_c offsets the
autocollimator null, eqs. 3.21-3.22)."""

from __future__ import annotations

from typing import Protocol

from drivers.can_link import CanLink
from drivers.canopen_dac import CanopenDac
from drivers.rig_datasheet import AXES, RigCalibration
from drivers.setpoints import SetpointKind, SetpointLimits, check_name

#: DAC outputs on the command node, in index order.
OUTPUTS = tuple(f"vtd_{a}" for a in AXES) + tuple(f"gc_{a}" for a in AXES)


class CommandDac(Protocol):
    """The command DACs (V_Td and gamma_c per axis), whatever the wire."""

    axes: tuple[str, ...]
    limits: SetpointLimits

    def set_command_torque_V(self, axis: str, volts: float) -> float:
        """Set V_Td on ``axis`` (checked against ``limits`` first); returns the read-back (V)."""
        ...

    def put_command_torque_V(self, axis: str, volts: float) -> float:
        """One step of a stream of V_Td set-points on ``axis`` (checked against ``limits``
        first): sent unconfirmed (a receive PDO), read back by ``confirm`` at the stream's end;
        returns the volts sent."""
        ...

    def confirm(self) -> None:
        """Read back every output a stream set; a difference is a latched ``ProtocolError``."""
        ...

    def put_ac_bias_V(self, axis: str, volts: float) -> float:
        """One step of a stream of gamma_c set-points on ``axis`` (checked against ``limits``
        first): sent unconfirmed (a receive PDO), read back by ``confirm`` at the stream's end;
        returns the volts sent."""
        ...

    def set_ac_bias_V(self, axis: str, volts: float) -> float:
        """Set gamma_c on ``axis`` (checked against ``limits`` first); returns the read-back (V)."""
        ...

    def command_torque_V(self, axis: str) -> float:
        """V_Td on ``axis`` as the node reads it back (V)."""
        ...

    def ac_bias_V(self, axis: str) -> float:
        """gamma_c on ``axis`` as the node reads it back (V)."""
        ...

    def zero(self) -> None:
        """Every output to 0 V (part of the safe state)."""
        ...


class CanopenCommandDac(CanopenDac):
    """The command DACs on a CiA 401 analogue-output node (``drivers/eds/command.eds``),
    outputs 1-6 in ``OUTPUTS`` order."""

    axes: tuple[str, ...] = AXES

    def __init__(self, link: CanLink, calibration: RigCalibration | None = None) -> None:
        super().__init__(link, "command", len(OUTPUTS), calibration)

    def set_command_torque_V(self, axis: str, volts: float) -> float:
        v = self.limits.command(SetpointKind.COMMAND_TORQUE, axis, volts)
        return self.write(OUTPUTS.index(f"vtd_{axis}"), v, f"vtd_{axis}")

    def put_command_torque_V(self, axis: str, volts: float) -> float:
        v = self.limits.command(SetpointKind.COMMAND_TORQUE, axis, volts)
        return self.stream(OUTPUTS.index(f"vtd_{axis}"), v, f"vtd_{axis}")

    def set_ac_bias_V(self, axis: str, volts: float) -> float:
        v = self.limits.command(SetpointKind.AC_BIAS, axis, volts)
        return self.write(OUTPUTS.index(f"gc_{axis}"), v, f"gc_{axis}")

    def put_ac_bias_V(self, axis: str, volts: float) -> float:
        v = self.limits.command(SetpointKind.AC_BIAS, axis, volts)
        return self.stream(OUTPUTS.index(f"gc_{axis}"), v, f"gc_{axis}")

    def command_torque_V(self, axis: str) -> float:
        return self.read(OUTPUTS.index(f"vtd_{check_name('axis', axis, self.axes)}"), f"vtd_{axis}")

    def ac_bias_V(self, axis: str) -> float:
        return self.read(OUTPUTS.index(f"gc_{check_name('axis', axis, self.axes)}"), f"gc_{axis}")

    def zero(self) -> None:
        for a in self.axes:
            self.set_command_torque_V(a, 0.0)
            self.set_ac_bias_V(a, 0.0)
