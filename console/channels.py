"""The ADC channels by the names of DESIGN.md section 5, with a short description each.

Every panel names a channel the way the run files, ``fbs spectra`` and the recording's channel
box do (``gyro_x``, never "pickoff X"); the description only follows the name, where there is
room. A name typed wrong is answered with the valid names (and the name meant, when the typed
text is a description).
"""

from __future__ import annotations

from collections.abc import Iterable

#: DESIGN.md section 5, in its order
DESCRIPTIONS: dict[str, str] = {
    "ac_x_ctl": "autocollimator X control",
    "ac_y_ctl": "autocollimator Y control",
    "ac_x_inst": "autocollimator X instrumentation",
    "ac_y_inst": "autocollimator Y instrumentation",
    "ac_z": "autocollimator azimuth",
    "gyro_x": "gyro pickoff X",
    "gyro_y": "gyro pickoff Y",
    "gyro_z": "gyro pickoff Z",
    "gyro_xrd": "gyro pickoff XRD",
    "torq_x": "torquer output X",
    "torq_y": "torquer output Y",
    "torq_z": "torquer output Z",
    "torq_xrd": "torquer output XRD",
    "pa_x": "power-amplifier input X",
    "pa_y": "power-amplifier input Y",
    "pa_z": "power-amplifier input Z",
    "cmd_x": "command input X",
    "cmd_y": "command input Y",
    "cmd_z": "command input Z",
}

#: the few words a meter row has room for
SHORT: dict[str, str] = {
    "gyro": "pickoff",
    "torq": "torquer",
    "ac": "autocoll",
    "pa": "power amp",
    "cmd": "command",
}


def short(channel: str) -> str:
    """``gyro_x`` -> ``pickoff``: what kind of signal, in a word."""
    return SHORT.get(channel.split("_", 1)[0], "")


def describe(channel: str) -> str:
    """``gyro_x`` -> ``gyro_x (gyro pickoff X)``; an unknown name as it is."""
    what = DESCRIPTIONS.get(channel)
    return f"{channel} ({what})" if what else channel


def meant(typed: str) -> str | None:
    """The channel a description names (``pickoff X``, ``torquer X``), or None."""
    t = " ".join(typed.lower().replace("_", " ").split())
    if not t:
        return None
    for ch, what in DESCRIPTIONS.items():
        w = what.lower()
        if t in (w, ch.replace("_", " "), f"{short(ch)} {ch.split('_')[1]}"):
            return ch
    return None


def unknown_channels(typed: Iterable[str], valid: Iterable[str], where: str) -> str | None:
    """Why some ``typed`` names are not channels of ``where`` (listing the valid ones), or None."""
    valid = tuple(valid)
    bad = [c for c in typed if c not in valid]
    if not bad:
        return None
    hints = [f"{c!r} is {m}" for c in bad if (m := meant(c)) is not None and m in valid]
    text = (
        f"{where} has no channel {', '.join(repr(c) for c in bad)}"
        + (f" ({'; '.join(hints)})" if hints else "")
        + f"; its channels: {', '.join(valid)}"
    )
    return text
