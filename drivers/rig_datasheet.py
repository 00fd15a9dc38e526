"""What the host knows about the rig before it measures anything: its data sheet.

These are the instrument constants a lab takes from data sheets and earlier calibrations
(DESIGN.md section 3; thesis Ch. II-III, Tables 1 and 4): the site, the platform's inertia,
motor and amplifier constants, the autocollimator scale factors. Drivers use them to check
set-points before sending them (the torquer bias limit is the voltage that torques at
3.5 x earth rate with the *nominal* torquer scale factor); procedures use them to turn volts
into torques and angles. The quantities the calibration procedures measure (K_TO, K_g,
drift, the bearing's To and eta, the table's azimuth offset) are here only as nominal values
for limits and as a last-resort fallback, never as results.
"""

from __future__ import annotations

from dataclasses import dataclass, field

GYRO_CHANNELS = ("X", "Y", "Z", "XRD")
#: the two two-degree-of-freedom gyros' input-axis pairs (a, b), with (a, b, spin) right-handed
#: (docs/simhw.md section 3): the X-Y gyro (spin along platform Z) and the X-Z gyro (spin along
#: Y, channels Z and XRD); viscous float drag couples a pair (II C.4.d)
GYRO_PAIRS = (("X", "Y"), ("Z", "XRD"))
#: the channel sharing each channel's float
FLOAT_PARTNER = {c: d for a, b in GYRO_PAIRS for c, d in ((a, b), (b, a))}
#: how far a unit's viscous coupling h/c may lie from its data sheet's (Table 3), a fraction:
#: what the procedures that use h/c carry in their intervals
VISCOUS_COUPLING_TOLERANCE = 0.3
#: how far a unit's pickoff scale K_g may lie from its data sheet's, a fraction: what a figure
#: read through the data sheet's K_g carries (issue 38: units drawn x0.8-1.2 put XRD's K_TO 4 of
#: 40 times outside an interval that took the restraint term as good to 20 %)
PICKOFF_SCALE_TOLERANCE = 0.2
AXES = ("X", "Y", "Z")
EARTH_RATE_RAD_PER_S = 7.292115e-5
#: the ADC's channels, volts (DESIGN.md section 5): autocollimator control and instrumentation,
#: azimuth; gyro pickoffs; torquer outputs; power-amplifier inputs; command inputs
ADC_CHANNELS = (
    "ac_x_ctl",
    "ac_y_ctl",
    "ac_x_inst",
    "ac_y_inst",
    "ac_z",
    "gyro_x",
    "gyro_y",
    "gyro_z",
    "gyro_xrd",
    "torq_x",
    "torq_y",
    "torq_z",
    "torq_xrd",
    "pa_x",
    "pa_y",
    "pa_z",
    "cmd_x",
    "cmd_y",
    "cmd_z",
)


@dataclass(frozen=True)
class PlatformConstants:
    """One gimbal axis (Ch. III C-E): what turns the power-amplifier input into torque."""

    inertia_kg_m2: float
    damping_Nms: float  # gyro-gimbal viscous damping on the platform, D (eq. 3.31)
    amp_gain: float  # Kp
    motor_Nm_per_A: float  # Km
    back_emf_V_s: float  # Kb
    armature_ohm: float  # Ra
    armature_H: float = 0.023  # La (eq. 3.25)
    command_divider: float = 0.0075  # Kd: V_Td into the amplifier input (eq. 3.27)

    @property
    def torque_per_pa_V(self) -> float:
        """N m of motor torque per volt at the power-amplifier input, Kp Km / Ra (eq. 3.24-3.27)."""
        return self.amp_gain * self.motor_Nm_per_A / self.armature_ohm

    @property
    def viscous_Nms(self) -> float:
        """All viscous torque per rad/s: gyro damping plus the motor's back-EMF, D + Km Kb / Ra."""
        return self.damping_Nms + self.motor_Nm_per_A * self.back_emf_V_s / self.armature_ohm


@dataclass(frozen=True)
class AutocollimatorConstants:
    """Primary autocollimator scale factors (Table 1)."""

    control_mV_per_urad: float
    inst_mV_per_urad: float
    #: the channels' filters (Table 1, eqs. 3.21-3.22): control 2nd order; instrumentation
    #: 1st order then 2nd order
    control_filter_rad_per_s: float = 264.0
    control_filter_zeta: float = 0.71
    inst_filter1_rad_per_s: float = 755.0
    inst_filter2_rad_per_s: float = 1250.0
    inst_filter2_zeta: float = 0.71


def _platform_defaults() -> dict[str, PlatformConstants]:
    return {
        "X": PlatformConstants(0.70, 1.02, 302.0, 0.53, 0.53, 23.0),
        "Y": PlatformConstants(0.25, 0.51, 164.0, 0.53, 0.53, 23.0),
        "Z": PlatformConstants(0.52, 0.51, 333.0, 0.53, 0.53, 23.0),
    }


def _ac_defaults() -> dict[str, AutocollimatorConstants]:
    return {"X": AutocollimatorConstants(5.70, 5.63), "Y": AutocollimatorConstants(5.99, 5.92)}


@dataclass(frozen=True)
class RigCalibration:
    torquer_scale_urad_per_s_per_V: dict[str, float] = field(
        default_factory=lambda: {"X": 31.6, "Y": 33.4, "Z": 34.1, "XRD": 32.0}
    )
    #: nominal pickoff scale factors: a fallback when no stopwatch result is at hand
    pickoff_scale_mV_per_urad: dict[str, float] = field(
        default_factory=lambda: {"X": 6.03, "Y": 6.70, "Z": 7.51, "XRD": 5.74}
    )
    #: the floats' elastic-restraint time constants h/k (s; Table 3): a standing pickoff angle
    #: sigma is balanced by the rate sigma / (h/k) without torquer current
    restraint_time_constant_s: dict[str, float] = field(
        default_factory=lambda: {"X": 424.0, "Y": 708.0, "Z": 1072.0, "XRD": 515.0}
    )
    #: the floats' viscous cross-axis coupling h/c (s; Table 3, II C.4.d): a float partner's
    #: rate precesses this one by (c/h) of it, so the X-Y gyro's Y pickoff reads
    #: theta_Y - (c/h)_X theta_X (the survey and drift undo it; the stopwatch models it)
    viscous_coupling_h_over_c: dict[str, float] = field(
        default_factory=lambda: {"X": 1.96, "Y": 21.0, "Z": 35.7, "XRD": 2.43}
    )
    #: the caging loops as designed (II C.1.a(8)): natural frequency (rad/s) and damping. In the
    #: gyro modes the autocollimator cages the float through them, inside the stabilization loop
    caging_natural_rad_per_s: dict[str, float] = field(
        default_factory=lambda: {"X": 0.1, "Y": 0.1, "Z": 0.1, "XRD": 1.0}
    )
    caging_zeta: dict[str, float] = field(
        default_factory=lambda: {"X": 0.7, "Y": 0.7, "Z": 0.7, "XRD": 1.0}
    )
    max_torquing_earth_rates: float = 3.5
    dac_range_V: float = 10.0
    dac_bits: int = 16
    latitude_deg: float = 37.43
    earth_rate_rad_per_s: float = EARTH_RATE_RAD_PER_S
    platform: dict[str, PlatformConstants] = field(default_factory=_platform_defaults)
    autocollimator: dict[str, AutocollimatorConstants] = field(default_factory=_ac_defaults)
    #: the azimuth (Z) reference autocollimator's scale (Table 1)
    azimuth_mV_per_urad: float = 7.36
    #: linear ranges: the primary autocollimator's (Table 1) and the gyro pickoffs' (II C.1.a)
    ac_linear_range_urad: float = 2300.0
    pickoff_linear_range_urad: float = 1000.0

    @property
    def dac_lsb_V(self) -> float:
        return 2.0 * self.dac_range_V / 2**self.dac_bits

    def torquer_limit_V(self, channel: str) -> float:
        """Bias voltage that torques at the rate limit, or the DAC range if that is lower."""
        kto = self.torquer_scale_urad_per_s_per_V[channel] * 1e-6
        return min(self.dac_range_V, self.max_torquing_earth_rates * EARTH_RATE_RAD_PER_S / kto)
