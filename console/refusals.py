"""Refusals in the operator's words: what was refused, why, and what to do.

A CAN node refuses with an SDO abort, and the driver's text names the object and the abort
code ("CAN node 'relay' (id 3) object 0x2002:0 refused SELECT mode 2: Code 0x08000021, Data
can not be transferred ..."): right for ``console.log``, wrong for an operator who pressed a
key out of turn. ``operator_words`` is the one place that turns such a driver error into the
sentence the console shows (its alarm lamp, notification, panel line and event log); the rig
thread logs the raw text beside it. Errors the drivers already word for an operator (the
interlocks of ``relay.interlock_reason``, a set-point limit, a disallowed mode) carry no
protocol text and pass through unchanged.
"""

from __future__ import annotations

import re

from drivers.canopen_client import ABORT_NOT_HELD, ABORT_NOT_OPERATIONAL
from drivers.errors import DeviceTimeout, InterlockError, ProtocolError, SetpointRangeError

#: ``CanopenClient._where``: the mark of a node's raw refusal or fault
_RAW = re.compile(r"CAN node '(?P<node>[^']*)' \(id \d+\) object 0x[0-9a-fA-F]{4}:\d+")
#: what to do about each reason the relay node gives (``relay.REASONS``)
_TO_DO = {
    "gyros not at speed": "spin them up in mode 2 (h 2 r) until the wheels are at speed",
    "gyros not caged": "cage them in mode 3 (h 3 r): each loop cages once its pickoff nulls",
    "mode outside 1-3": "switch to mode 3 first",
    "a command input not at zero": "set V_Td and gamma_c to 0 V on Set-points (F3)",
}
HOW_TO_SELECT = "press h (hold), then the mode's digit, then r (release)"


def operator_words(what: str, exc: BaseException) -> str:
    """The sentence an operator reads for the refused or failed command ``what`` (the rig
    thread's command name: "select mode 2", "release", "torquer bias X", ...)."""
    text = str(exc)
    raw = _RAW.search(text)
    if raw is None:
        return text  # already in words: the drivers' or the console's own
    node = raw["node"]
    if isinstance(exc, InterlockError):
        if exc.detail == ABORT_NOT_HELD:
            if what.startswith("select mode "):
                mode = what.removeprefix("select mode ")
                return (
                    f"mode {mode} not selected: the mode switches are not held; "
                    f"press h (hold), then {mode}, then r (release)"
                )
            if what == "release":
                return f"nothing to release: the mode switches are not held; {HOW_TO_SELECT}"
            return f"{what} refused: the mode switches are not held; {HOW_TO_SELECT}"
        if exc.detail == ABORT_NOT_OPERATIONAL:
            return (
                f"{what} refused: the {node} node is latched in its safe state (not "
                "operational); quit and reopen the console, which starts it again"
            )
        if exc.reasons:
            why = "; ".join(exc.reasons)
            do = "; ".join(_TO_DO[r] for r in exc.reasons if r in _TO_DO)
            return f"{what} refused by the interlocks: {why}" + (f"; {do}" if do else "")
        return f"{what} refused by the {node} node's interlocks: see Modes (F2) for what is missing"
    if isinstance(exc, SetpointRangeError):
        return (
            f"{what} refused: the {node} node does not take that value (outside its range); "
            "nothing changed: enter a value within the limit shown on Set-points (F3)"
        )
    if isinstance(exc, DeviceTimeout):
        return (
            f"{what} failed: the {node} node did not answer; the rig went safe "
            "(console.log has the detail)"
        )
    if isinstance(exc, ProtocolError):
        return (
            f"{what} failed: the {node} node's answer was not understood; the rig went safe "
            "(console.log has the detail)"
        )
    return f"{what} failed at the {node} node (console.log has the detail)"
