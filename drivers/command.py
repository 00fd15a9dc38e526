"""The command DACs: platform command torque V_Td and autocollimator bias gamma_c per axis
(Ch. III: V_Td enters the power amplifier through the divider Kd; gamma_c offsets the
autocollimator null, eqs. 3.21-3.22)."""

from __future__ import annotations

from typing import Protocol

from drivers import can_protocol as cp
from drivers.calibration import AXES, RigCalibration
from drivers.can_link import CanLink, NodeClient
from drivers.setpoints import SetpointKind, SetpointLimits, check_name
from drivers.torquer import check_readback

#: DAC outputs on the command node, in index order.
OUTPUTS = tuple(f"vtd_{a}" for a in AXES) + tuple(f"gc_{a}" for a in AXES)


class CommandDac(Protocol):
    """The command DACs (V_Td and gamma_c per axis), whatever the wire."""

    axes: tuple[str, ...]
    limits: SetpointLimits

    def set_command_torque_V(self, axis: str, volts: float) -> float: ...

    def set_ac_bias_V(self, axis: str, volts: float) -> float: ...

    def command_torque_V(self, axis: str) -> float: ...

    def ac_bias_V(self, axis: str) -> float: ...

    def zero(self) -> None: ...


class CanCommandDac:
    """The command DACs on their CAN node."""

    axes: tuple[str, ...] = AXES

    def __init__(self, link: CanLink, calibration: RigCalibration | None = None) -> None:
        self.limits = SetpointLimits(calibration or RigCalibration())
        self.node = NodeClient(link, "command")

    def set_command_torque_V(self, axis: str, volts: float) -> float:
        return self._set(f"vtd_{axis}", self.limits.command(SetpointKind.COMMAND_TORQUE, axis, volts))

    def set_ac_bias_V(self, axis: str, volts: float) -> float:
        return self._set(f"gc_{axis}", self.limits.command(SetpointKind.AC_BIAS, axis, volts))

    def command_torque_V(self, axis: str) -> float:
        return self._get(f"vtd_{check_name('axis', axis, self.axes)}")

    def ac_bias_V(self, axis: str) -> float:
        return self._get(f"gc_{check_name('axis', axis, self.axes)}")

    def zero(self) -> None:
        for a in self.axes:
            self.set_command_torque_V(a, 0.0)
            self.set_ac_bias_V(a, 0.0)

    def _set(self, output: str, volts: float) -> float:
        back = cp.from_micro(self.node.call(cp.OP_SET, OUTPUTS.index(output), cp.to_micro(volts),
                                            what=f"{output} = {volts:+.6f} V"))
        return check_readback(self.node, output, volts, back, self.limits.calibration.dac_lsb_V)

    def _get(self, output: str) -> float:
        return cp.from_micro(self.node.call(cp.OP_GET, OUTPUTS.index(output), what=f"read {output}"))
