"""What the host must know about the rig to check set-points before sending them.

These are the rig's nominal values (DESIGN.md section 3; thesis Table 4, II C.1.a(1)), used
only for limits, never as measurement results: the torquer bias limit is the voltage that
torques at 3.5 x earth rate with the nominal torquer scale factor.
"""

from __future__ import annotations

from dataclasses import dataclass, field

GYRO_CHANNELS = ("X", "Y", "Z", "XRD")
AXES = ("X", "Y", "Z")
EARTH_RATE_RAD_PER_S = 7.292115e-5


@dataclass(frozen=True)
class RigCalibration:
    torquer_scale_urad_per_s_per_V: dict[str, float] = field(
        default_factory=lambda: {"X": 31.6, "Y": 33.4, "Z": 34.1, "XRD": 32.0})
    max_torquing_earth_rates: float = 3.5
    dac_range_V: float = 10.0
    dac_bits: int = 16

    @property
    def dac_lsb_V(self) -> float:
        return 2.0 * self.dac_range_V / 2 ** self.dac_bits

    def torquer_limit_V(self, channel: str) -> float:
        """Bias voltage that torques at the rate limit, or the DAC range if that is lower."""
        kto = self.torquer_scale_urad_per_s_per_V[channel] * 1e-6
        return min(self.dac_range_V, self.max_torquing_earth_rates * EARTH_RATE_RAD_PER_S / kto)
