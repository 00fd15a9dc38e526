"""The meter panel's data: which channels are the ten permanent meters, their engineering
units, and the store the rig thread fills and the UI reads.

The thesis's meter panel (II C.2) showed the four gyro pickoffs, the four torquer outputs
and the two autocollimator control channels. Volts become engineering units with the rig's
data sheet (``RigCalibration``): pickoff angle = V / K_g, torquing rate = V x K_TO,
autocollimator angle = V / (control scale factor).
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from console.channels import short
from drivers.rig_datasheet import GYRO_CHANNELS, RigCalibration


@dataclass(frozen=True)
class MeterSpec:
    """One permanent meter: an ADC channel (named as in DESIGN.md section 5, as every panel
    names it) and its conversion to engineering units."""

    channel: str
    units: str
    per_volt: float  # engineering units per volt at the ADC

    @property
    def what(self) -> str:
        """The kind of signal in a word (``pickoff``), shown beside the channel's name."""
        return short(self.channel)

    def eng(self, volts: float) -> float:
        return volts * self.per_volt


def permanent_meters(cal: RigCalibration) -> tuple[MeterSpec, ...]:
    """The ten meters of the thesis's meter panel, in its order."""
    gyros = tuple(
        MeterSpec(f"gyro_{c.lower()}", "urad", 1e3 / cal.pickoff_scale_mV_per_urad[c])
        for c in GYRO_CHANNELS
    )
    torquers = tuple(
        MeterSpec(f"torq_{c.lower()}", "urad/s", cal.torquer_scale_urad_per_s_per_V[c])
        for c in GYRO_CHANNELS
    )
    acs = tuple(
        MeterSpec(f"ac_{a.lower()}_ctl", "urad", 1e3 / cal.autocollimator[a].control_mV_per_urad)
        for a in ("X", "Y")
    )
    return gyros + torquers + acs


@dataclass(frozen=True)
class MeterSnapshot:
    """What the UI draws: each channel's latest reading (V) and its strip-chart points."""

    seq: int  # bumps whenever new samples arrived
    volts: dict[str, float] = field(default_factory=dict)
    history: dict[str, tuple[float, ...]] = field(default_factory=dict)
    rig_time_s: float = 0.0


class MeterStore:
    """Filled by the rig thread with every block the ADC delivers; read by the UI.

    A reading is the mean of the last ``average_s`` of samples (a panel meter's damping,
    so 1 kHz noise does not make the digits unreadable); a strip-chart point is the mean of
    ``point_s`` of samples, ``history`` points kept per channel.
    """

    def __init__(self, *, average_s: float = 0.1, point_s: float = 0.2, history: int = 150) -> None:
        self.average_s = average_s
        self.point_s = point_s
        self._history = history
        self._lock = threading.Lock()
        self._seq = 0
        self._volts: dict[str, float] = {}
        self._points: dict[str, deque[float]] = {}
        self._acc: dict[str, tuple[float, int]] = {}  # partial strip-chart point: (sum, count)
        self._rig_time = 0.0
        self._rate = 0.0

    def push(
        self, channels: tuple[str, ...], volts: np.ndarray, rate_hz: float, rig_time_s: float = 0.0
    ) -> None:
        if len(volts) == 0:
            return
        n_avg = max(1, int(round(self.average_s * rate_hz)))
        with np.errstate(all="ignore"):
            latest = (
                np.nanmean(volts[-n_avg:], axis=0) if np.isfinite(volts[-n_avg:]).any() else None
            )
        per_point = max(1, int(round(self.point_s * rate_hz)))
        with self._lock:
            self._seq += 1
            self._rig_time = rig_time_s
            if (
                rate_hz != self._rate
            ):  # a partial point at another rate cannot be finished at this one
                self._acc.clear()
                self._rate = rate_hz
            for j, ch in enumerate(channels):
                if latest is not None:
                    self._volts[ch] = float(latest[j])
                col = volts[:, j]
                s, k = self._acc.get(ch, (0.0, 0))
                pts = self._points.setdefault(ch, deque(maxlen=self._history))
                # whole points first (vectorised: a procedure in virtual time hands over
                # seconds of samples at once), the remainder carried to the next block
                i = 0
                if k:
                    take = min(per_point - k, len(col))
                    s, k, i = s + float(np.nansum(col[:take])), k + take, take
                    if k == per_point:
                        pts.append(s / k)
                        s, k = 0.0, 0
                whole = (len(col) - i) // per_point
                if whole:
                    with np.errstate(all="ignore"):
                        means = np.nanmean(
                            col[i : i + whole * per_point].reshape(whole, per_point), axis=1
                        )
                    pts.extend(means[-self._history :].tolist())
                    i += whole * per_point
                rest = col[i:]
                if len(rest):
                    s, k = s + float(np.nansum(rest)), k + len(rest)
                self._acc[ch] = (s, k)

    def snapshot(self, with_history: tuple[str, ...] = ()) -> MeterSnapshot:
        with self._lock:
            return MeterSnapshot(
                self._seq,
                dict(self._volts),
                {c: tuple(self._points.get(c, ())) for c in with_history},
                self._rig_time,
            )

    def clear(self) -> None:
        """Forget the readings (the stream stopped: stale digits would mislead)."""
        with self._lock:
            self._seq += 1
            self._volts.clear()
            self._acc.clear()
