"""Checks every set-point passes before a byte leaves the host.

``SetpointLimits`` is the one place the rig's set-point limits live: pure checks on the rig's
data sheet (``RigCalibration``) that send nothing. The DAC drivers call them before every
frame, and the console calls the same ones on what the operator typed, so a refusal names the
value and the limit in the same words wherever it happens.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from enum import StrEnum

from drivers.errors import SetpointRangeError
from drivers.rig_datasheet import AXES, GYRO_CHANNELS, RigCalibration


class SetpointKind(StrEnum):
    """The rig's analogue set-points; the value is the name messages use."""

    TORQUER_BIAS = "torquer bias"  # per gyro channel (II C.1.a(1))
    COMMAND_TORQUE = "command torque V_Td"  # per platform axis, through Kd (Ch. III)
    AC_BIAS = "autocollimator bias gamma_c"  # per platform axis (eqs. 3.21-3.22)


def check_name(what: str, name: object, allowed: Iterable[str]) -> str:
    allowed = tuple(allowed)
    if name not in allowed:
        raise SetpointRangeError(
            f"{what} {name!r} does not exist (choose one of {', '.join(allowed)}); nothing was sent",
            value=name,
            limit=allowed,
        )
    return str(name)


def check_value(what: str, value: object, limit: float, why: str, lo: float | None = None) -> float:
    """``value`` as a float within ``[lo, limit]`` (``lo`` defaults to ``-limit``), else SetpointRangeError."""
    lo = -limit if lo is None else lo
    try:
        v = float(value)  # type: ignore[arg-type]  # whatever float() takes: typed text, numpy scalars
    except (TypeError, ValueError):
        raise SetpointRangeError(
            f"{what} {value!r} is not a number; nothing was sent", value=value
        ) from None
    if not math.isfinite(v) or not lo <= v <= limit:
        span = f"+-{limit:g}" if lo == -limit else f"{lo:g}..{limit:g}"
        raise SetpointRangeError(
            f"{what} {value!r} is outside {span} ({why}); nothing was sent",
            value=value,
            limit=limit,
        )
    return v


@dataclass(frozen=True)
class SetpointLimits:
    """The set-point limits of a rig with this data sheet; every check returns the value as a
    float or raises ``SetpointRangeError`` naming the value and the limit."""

    calibration: RigCalibration

    def torquer_limit_V(self, channel: str) -> float:
        """The largest torquer bias (V) on ``channel``: 3.5 x earth rate at K_TO, or the DAC range."""
        return self.calibration.torquer_limit_V(check_name("gyro channel", channel, GYRO_CHANNELS))

    def torquer_bias(self, channel: str, volts: object) -> float:
        lim = self.torquer_limit_V(channel)
        cal = self.calibration
        kto = cal.torquer_scale_urad_per_s_per_V[channel]
        why = (
            f"the torquer's {cal.max_torquing_earth_rates:g} x earth-rate limit at K_TO {kto:g} urad/s/V"
            if lim < cal.dac_range_V
            else "the DAC's range"
        )
        return check_value(
            f"{SetpointKind.TORQUER_BIAS} (V) on gyro channel {channel}", volts, lim, why
        )

    def command(self, kind: SetpointKind, axis: str, volts: object) -> float:
        """A command DAC output (V_Td or gamma_c) on platform ``axis``."""
        if kind is SetpointKind.TORQUER_BIAS:
            raise ValueError("a torquer bias is per gyro channel: use torquer_bias")
        check_name("axis", axis, AXES)
        return check_value(
            f"{kind} (V) on axis {axis}", volts, self.calibration.dac_range_V, "the DAC's range"
        )
