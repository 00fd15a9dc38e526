"""The simulated rig's data sheet: the instrument constants a lab would know beforehand.

``rig_calibration(cfg)`` publishes, for a sim config, what a real rig's calibration file
holds (``drivers.rig_datasheet``): site, platform inertia, motor and amplifier constants,
autocollimator scale factors and filters, the caging loops' design. It deliberately does *not*
publish what the procedures measure: torquer and pickoff scale factors, drifts, bearing friction and the table's azimuth
offset stay at their nominal (thesis) values, whatever the config says, so a procedure run
against another config must find those by measurement.
"""

from __future__ import annotations

from drivers.rig_datasheet import AutocollimatorConstants, PlatformConstants, RigCalibration
from simhw.config import AC_AXES, AXES, SimConfig


def rig_calibration(cfg: SimConfig) -> RigCalibration:
    platform = {
        a: PlatformConstants(
            inertia_kg_m2=p.inertia_kg_m2,
            damping_Nms=p.gyro_damping_Nms,
            amp_gain=p.amp_gain,
            motor_Nm_per_A=p.motor_torque_Nm_per_A,
            back_emf_V_s=p.back_emf_V_s,
            armature_ohm=p.armature_ohm,
            armature_H=p.armature_H,
            command_divider=p.command_divider,
        )
        for a, p in ((a, cfg.platform[a]) for a in AXES)
    }
    ac = {
        a: AutocollimatorConstants(
            c.control_scale_mV_per_urad,
            c.inst_scale_mV_per_urad,
            control_filter_rad_per_s=c.control_filter_rad_per_s,
            control_filter_zeta=c.control_filter_zeta,
            inst_filter1_rad_per_s=c.inst_filter1_rad_per_s,
            inst_filter2_rad_per_s=c.inst_filter2_rad_per_s,
            inst_filter2_zeta=c.inst_filter2_zeta,
        )
        for a, c in ((a, cfg.autocollimator[a]) for a in AC_AXES)
    }
    return RigCalibration(
        latitude_deg=cfg.site.latitude_deg,
        earth_rate_rad_per_s=cfg.site.earth_rate_rad_per_s,
        platform=platform,
        autocollimator=ac,
        caging_natural_rad_per_s={c: g.caging_natural_freq_rad_per_s for c, g in cfg.gyro.items()},
        caging_zeta={c: g.caging_zeta for c, g in cfg.gyro.items()},
    )
