"""How long the gyro wheels still need to reach speed (mode 2, spin-up).

The console does not know a wheel's run-up time (a real rig's motors have their own); it
watches the relay node's speed read-back (the slowest wheel, in whole percent) on rig time and
fits the first-order run-up a synchronous motor's wheel follows, f(t) = 1 - (1 - f0) e^(-t/tau):
two readings give tau = dt / ln((1 - f1) / (1 - f2)), and the time left to ``AT_SPEED``
follows. The read-back moves in 1 % steps: a reading is kept when it first shows a new value,
the moment the wheel crossed it (a reading in mid-step would be up to a step stale, which near
full speed is many seconds). The readings are a window of ``window_s`` of rig time (a wheel
that is not first order is judged by its recent run-up), and no estimate is made before the
speed has moved ``min_rise``.
"""

from __future__ import annotations

import math
from collections import deque

#: the fraction of operating speed at which the relay node reports a wheel at speed
AT_SPEED = 0.99


class SpinUpEstimate:
    def __init__(self, *, window_s: float = 120.0, min_rise: float = 0.03) -> None:
        self.window_s = window_s
        self.min_rise = min_rise
        self._seen: deque[tuple[float, float]] = deque()

    def observe(self, t_s: float, fraction: float, spinning_up: bool) -> float | None:
        """A speed read-back at rig time ``t_s``; the seconds (rig time) left to speed, or None
        when not spinning up or not yet measurable."""
        if not spinning_up or fraction >= AT_SPEED:
            self._seen.clear()
            return None
        if self._seen and (fraction < self._seen[-1][1] or t_s < self._seen[-1][0]):
            self._seen.clear()  # slowing down, or a new rig clock: start again
        if not self._seen or fraction > self._seen[-1][1]:
            self._seen.append((t_s, fraction))
        while len(self._seen) > 2 and t_s - self._seen[1][0] >= self.window_s:
            self._seen.popleft()
        return self.remaining_s(t_s)

    def remaining_s(self, now_s: float) -> float | None:
        """Seconds of rig time from ``now_s`` until the wheels are at speed, or None."""
        if len(self._seen) < 2:
            return None
        (t1, f1), (t2, f2) = self._seen[0], self._seen[-1]
        if f2 - f1 < self.min_rise or t2 <= t1:
            return None
        tau = (t2 - t1) / math.log((1.0 - f1) / (1.0 - f2))
        return max(0.0, tau * math.log((1.0 - f2) / (1.0 - AT_SPEED)) - (now_s - t2))
