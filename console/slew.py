"""Torquer bias with slew: the bias goes to its target at a bounded rate, never in one jump.

A step in a torquer bias is a step in the gyro's commanded rate; the caging loops (natural
frequency 0.1 rad/s, II C.1.a) would see it as a kick. The console ramps instead: every tick
of the rig thread moves each bias at most ``rate x dt`` toward its target, in rig time.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class Slew:
    channel: str
    target_V: float
    rate_V_per_s: float
    now_V: float
    last_t: float
    steps: int = 0  # set-points sent so far
    start_V: float = field(init=False)
    t0: float = field(init=False)  # rig time the ramp began

    def __post_init__(self) -> None:
        self.start_V, self.t0 = self.now_V, self.last_t

    @property
    def done(self) -> bool:
        return self.now_V == self.target_V

    def step(self, t: float) -> float:
        """The next set-point at rig time ``t`` (the target once within reach)."""
        dt = max(0.0, t - self.last_t)
        self.last_t = t
        room = self.target_V - self.now_V
        move = self.rate_V_per_s * dt
        self.now_V = (
            self.target_V if abs(room) <= move else self.now_V + (move if room > 0 else -move)
        )
        self.steps += 1
        return self.now_V
