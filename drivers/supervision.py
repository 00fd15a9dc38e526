"""Supervision of the gyro modes while they are in force, not only at their entry.

Modes 4 and 5 are entered only with the gyros at speed and caged (the relay driver's
interlock, docs/protocol.md 2.5). Once in force, nothing at the node watches that they stay
so: a caging inhibit in Mode 4 lets a float run to its stop, its caging torquer saturates and
the platform follows the gyro off the autocollimator (about 20 s later ac_x_ctl sits on the
converter's rail, gyro_xrd pinned at -8.6 V, torq_xrd saturated). The host sees every sample
the ADC streams, so it watches them: in Mode 4 (all four gyro channels caged) or Mode 5 (X, Y,
XRD), an alarm is

* a caged channel's pickoff beyond its linear range (1 mrad at the data sheet's scale);
* its torquer output at ``TORQUER_SHARE`` of the torquing limit (3.5 x earth rate) or beyond;
* an autocollimator control channel beyond the autocollimator's linear range (2.3 mrad) or on
  the converter's end code (the ADC's +-10 V is 1.75 mrad at 5.7 mV/urad: the platform has
  left what the host can measure),

held for ``hold_s`` (0.5 s) without a break. The alarm is a ``SupervisionAlarm`` latched on
the rig's fault latch: the rig goes safe at once (Mode 1, biases and commands zero, read back),
and the command, procedure or console meets the fault on its next call. Only the channels
being streamed can be watched; the console and every procedure stream them.

Mode 3 is not supervised here: a hysteresis sweep or a pickoff stopwatch drives those
channels far on purpose, and the autocollimator loop itself holds the platform.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from drivers.adc import Adc, AdcBlock, AdcDecorator
from drivers.errors import DriverError
from drivers.faults import FaultLatch
from drivers.rig_datasheet import RigCalibration

log = logging.getLogger(__name__)

#: the caged channels of each supervised mode (Ch. II D)
CAGED = {4: ("X", "Y", "Z", "XRD"), 5: ("X", "Y", "XRD")}
#: a torquer output at this share of its torquing limit counts as saturated: the limit is the
#: data sheet's (nominal K_TO); a unit whose K_TO is 10 % above nominal saturates at 0.91 of it
TORQUER_SHARE = 0.85
HOLD_S = 0.5


class SupervisionAlarm(DriverError):
    """A gyro mode in force has lost what its entry required: the rig went safe."""


@dataclass(frozen=True)
class Watch:
    """One channel's limit in one mode: beyond ``limit_V`` (or on the converter's end code,
    where ``at_end_code``) is a violation; ``what`` says what that means."""

    channel: str
    limit_V: float
    what: str
    at_end_code: bool = False


def watches(calibration: RigCalibration, mode: int) -> list[Watch]:
    """What is watched in ``mode`` (none outside Modes 4 and 5)."""
    cal = calibration
    out: list[Watch] = []
    for c in CAGED.get(mode, ()):
        kg = cal.pickoff_scale_mV_per_urad[c] * 1e-3
        out.append(
            Watch(
                f"gyro_{c.lower()}",
                kg * cal.pickoff_linear_range_urad,
                f"beyond the pickoff's linear range ({cal.pickoff_linear_range_urad:g} urad)",
            )
        )
        limit = cal.torquer_limit_V(c)
        out.append(
            Watch(
                f"torq_{c.lower()}",
                TORQUER_SHARE * limit,
                f"at {TORQUER_SHARE:.0%} of its torquing limit ({limit:.3f} V) or beyond: saturated",
            )
        )
    if mode in CAGED:
        for a, ac in cal.autocollimator.items():
            k = ac.control_mV_per_urad * 1e-3
            out.append(
                Watch(
                    f"ac_{a.lower()}_ctl",
                    k * cal.ac_linear_range_urad,
                    f"beyond the autocollimator's linear range ({cal.ac_linear_range_urad:g} urad) or on "
                    "the converter's rail: the platform has run off",
                    at_end_code=True,
                )
            )
    return out


def longest_run(beyond: np.ndarray, carried: int) -> tuple[int, int]:
    """(longest run of True in ``beyond`` counting ``carried`` Trues before it, the run at its end)."""
    n = len(beyond)
    breaks = np.flatnonzero(~beyond)
    if len(breaks) == 0:
        return carried + n, carried + n
    inner = int(np.max(np.diff(breaks)) - 1) if len(breaks) > 1 else 0
    tail = n - 1 - int(breaks[-1])
    return max(carried + int(breaks[0]), inner, tail), tail


class ModeSupervisor:
    """Watches the blocks the host reads against the mode in force (``mode``, kept by the rig
    as it sets modes and goes safe); reports a ``SupervisionAlarm`` to ``faults`` once."""

    def __init__(
        self, calibration: RigCalibration, faults: FaultLatch, hold_s: float = HOLD_S
    ) -> None:
        self.calibration = calibration
        self.faults = faults
        self.hold_s = hold_s
        self._mode: int | None = None
        self._watches: list[Watch] = []
        self._runs: dict[str, int] = {}

    @property
    def mode(self) -> int | None:
        return self._mode

    @mode.setter
    def mode(self, mode: int | None) -> None:
        if mode != self._mode:
            self._mode = mode
            self._watches = watches(self.calibration, mode) if mode is not None else []
            self._runs = {}

    def observe(self, block: AdcBlock) -> None:
        if not self._watches or self.faults.fault is not None:
            return
        need = max(1, int(round(self.hold_s * block.rate_hz)))
        for w in self._watches:
            if w.channel not in block.channels:
                continue
            col = block.channels.index(w.channel)
            v = block.volts[:, col]
            beyond = np.abs(v) >= w.limit_V
            if w.at_end_code:
                beyond |= block.overrange[:, col]
            longest, self._runs[w.channel] = longest_run(beyond, self._runs.get(w.channel, 0))
            if longest >= need:
                t = block.t0_s + block.stop_sample / block.rate_hz
                self.faults.report(
                    SupervisionAlarm(
                        f"mode {self._mode} supervision at {t:.2f} s: {w.channel} = {v[-1]:+.3f} V, {w.what}, "
                        f"for {self.hold_s:g} s; the rig went safe (Mode 1). Check the caging switches and the "
                        f"gyros before entering mode {self._mode} again"
                    )
                )
                return


class SupervisedAdc(AdcDecorator):
    """The rig's ADC as every reader sees it: each block shown to the ``ModeSupervisor``."""

    def __init__(self, inner: Adc, supervisor: ModeSupervisor) -> None:
        super().__init__(inner)
        self.supervisor = supervisor

    def _deliver(self, block: AdcBlock) -> None:
        self.supervisor.observe(block)
