"""The command DACs: platform command torque V_Td and autocollimator bias gamma_c per axis
(Ch. III: V_Td enters the power amplifier through the divider Kd; gamma_c offsets the
autocollimator null, eqs. 3.21-3.22)."""

from __future__ import annotations

import abc

from drivers import can_protocol as cp
from drivers.calibration import AXES, RigCalibration
from drivers.can_link import CanLink, NodeClient
from drivers.setpoints import check_name, check_value
from drivers.torquer import check_readback

#: DAC outputs on the command node, in index order.
OUTPUTS = tuple(f"vtd_{a}" for a in AXES) + tuple(f"gc_{a}" for a in AXES)


class CommandDac(abc.ABC):
    axes = AXES

    def __init__(self, calibration: RigCalibration | None = None) -> None:
        self.calibration = calibration or RigCalibration()

    def _check(self, what: str, axis: str, volts: float) -> float:
        check_name("axis", axis, self.axes)
        return check_value(f"{what} (V) on axis {axis}", volts, self.calibration.dac_range_V, "the DAC's range")

    def set_command_torque_V(self, axis: str, volts: float) -> float:
        return self._set(f"vtd_{axis}", self._check("command torque V_Td", axis, volts))

    def set_ac_bias_V(self, axis: str, volts: float) -> float:
        return self._set(f"gc_{axis}", self._check("autocollimator bias gamma_c", axis, volts))

    def command_torque_V(self, axis: str) -> float:
        return self._get(f"vtd_{check_name('axis', axis, self.axes)}")

    def ac_bias_V(self, axis: str) -> float:
        return self._get(f"gc_{check_name('axis', axis, self.axes)}")

    def zero(self) -> None:
        for a in self.axes:
            self.set_command_torque_V(a, 0.0)
            self.set_ac_bias_V(a, 0.0)

    @abc.abstractmethod
    def _set(self, output: str, volts: float) -> float: ...

    @abc.abstractmethod
    def _get(self, output: str) -> float: ...


class CanCommandDac(CommandDac):
    def __init__(self, link: CanLink, calibration: RigCalibration | None = None) -> None:
        super().__init__(calibration)
        self.node = NodeClient(link, "command")

    def _set(self, output: str, volts: float) -> float:
        back = cp.from_micro(self.node.call(cp.OP_SET, OUTPUTS.index(output), cp.to_micro(volts),
                                            what=f"{output} = {volts:+.6f} V"))
        return check_readback(self.node, output, volts, back, self.calibration.dac_lsb_V)

    def _get(self, output: str) -> float:
        return cp.from_micro(self.node.call(cp.OP_GET, OUTPUTS.index(output), what=f"read {output}"))
