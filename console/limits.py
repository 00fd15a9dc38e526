"""Set-point checks on the UI thread, with the drivers' own rules and words.

A bad entry is refused before it leaves the console: the checks are the drivers' own pure
``drivers.setpoints.SetpointLimits`` on the rig's data sheet, so the messages name the value
and the limit exactly as the drivers do, and the rig thread's driver call checks again before
any byte is sent. Here only the typed text is turned into a number first.
"""

from __future__ import annotations

from enum import StrEnum

from drivers.setpoints import SetpointKind, SetpointLimits, check_value

#: torquer bias slew rate limits (V/s): slow enough for the caging loops to follow, and a
#: ramp never takes longer than a few minutes across the whole range
SLEW_MIN_V_PER_S = 0.01
SLEW_MAX_V_PER_S = 5.0
SLEW_DEFAULT_V_PER_S = 1.0


class Entry(StrEnum):
    """What a set-point panel entry commands; the value is its widget id's prefix."""

    TORQUER_BIAS = "torq"
    COMMAND_TORQUE = "vtd"
    AC_BIAS = "gc"
    CAGING = "cage"
    SLEW = "slew"

    @property
    def setpoint(self) -> SetpointKind:
        """The drivers' set-point this entry sets (not for the caging switches or the slew rate)."""
        return {
            Entry.TORQUER_BIAS: SetpointKind.TORQUER_BIAS,
            Entry.COMMAND_TORQUE: SetpointKind.COMMAND_TORQUE,
            Entry.AC_BIAS: SetpointKind.AC_BIAS,
        }[self]


def typed_setpoint(limits: SetpointLimits, entry: Entry, key: str, text: str) -> float:
    """The set-point (V) typed into ``entry`` for channel or axis ``key``; a
    ``drivers.errors.SetpointRangeError`` names the value and the limit."""
    kind = entry.setpoint
    if kind is SetpointKind.TORQUER_BIAS:
        return limits.torquer_bias(key, _number(text))
    return limits.command(kind, key, _number(text))


def typed_slew(text: str) -> float:
    """The torquer bias slew rate (V/s) typed, within the console's bounds."""
    return check_value(
        "torquer bias slew rate (V/s)",
        _number(text),
        SLEW_MAX_V_PER_S,
        "the console's bounded slew",
        lo=SLEW_MIN_V_PER_S,
    )


def _number(text: str) -> object:
    """A typed number, or the text itself so the driver's check names what was typed."""
    t = text.strip()
    try:
        return float(t)
    except ValueError:
        return t
