"""Set-point checks on the UI thread, with the drivers' own rules and words.

A bad entry is refused before it leaves the console: the checks are the drivers' own
(``TorquerDac.check_bias``, ``CommandDac._check``, ``drivers.setpoints.check_value``), run
on driver objects that hold only the rig's data sheet and can send nothing. The messages
name the value and the limit exactly as the drivers do, and the rig thread's driver call
checks again before any byte is sent.
"""

from __future__ import annotations

from dataclasses import dataclass

from drivers.calibration import RigCalibration
from drivers.command import CommandDac
from drivers.setpoints import check_value
from drivers.torquer import TorquerDac

#: torquer bias slew rate limits (V/s): slow enough for the caging loops to follow, and a
#: ramp never takes longer than a few minutes across the whole range
SLEW_MIN_V_PER_S = 0.01
SLEW_MAX_V_PER_S = 5.0
SLEW_DEFAULT_V_PER_S = 1.0


class _SilentTorquers(TorquerDac):
    """A torquer DAC with the rig's data sheet and no wire: only its checks are used."""

    def set_bias_V(self, channel: str, volts: float) -> float:
        raise NotImplementedError("limits only")

    def bias_V(self, channel: str) -> float:
        raise NotImplementedError("limits only")


class _SilentCommands(CommandDac):
    """A command DAC with the rig's data sheet and no wire: only its checks are used."""

    def _set(self, output: str, volts: float) -> float:
        raise NotImplementedError("limits only")

    def _get(self, output: str) -> float:
        raise NotImplementedError("limits only")


@dataclass(frozen=True)
class SetpointLimits:
    calibration: RigCalibration

    def torquer_limit_V(self, channel: str) -> float:
        return _SilentTorquers(self.calibration).limit_V(channel)

    def dac_range_V(self) -> float:
        return self.calibration.dac_range_V

    def torquer_bias(self, channel: str, text: str) -> float:
        """The bias (V) typed for ``channel``; ``drivers.errors.SetpointRangeError`` names the value
        and the limit."""
        return _SilentTorquers(self.calibration).check_bias(channel, _number(text))

    def command_torque(self, axis: str, text: str) -> float:
        return _SilentCommands(self.calibration)._check("command torque V_Td", axis, _number(text))

    def ac_bias(self, axis: str, text: str) -> float:
        return _SilentCommands(self.calibration)._check("autocollimator bias gamma_c", axis, _number(text))

    @staticmethod
    def slew(text: str) -> float:
        return check_value("torquer bias slew rate (V/s)", _number(text), SLEW_MAX_V_PER_S,
                           "the console's bounded slew", lo=SLEW_MIN_V_PER_S)


def _number(text: str) -> object:
    """A typed number, or the text itself so the driver's check names what was typed."""
    t = text.strip()
    try:
        return float(t)
    except ValueError:
        return t

