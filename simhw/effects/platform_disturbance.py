"""``platform_disturbance``: low-frequency disturbance torque on the gimbal (Ch. III H: M_d).

Not in the thesis's model, which under-predicted the closed-loop spectra below a few hertz
(Ch. V E). Floor motion, air currents and cable torques act as a torque noise: white torque
through a first-order lag at ``corner_hz``, of rms ``torque_rms_Nm``. docs/simhw.md gives the
size that brings the simulated platform motion up to the thesis's 1.6 / 3.6 urad.
"""

from simhw.effects import Effect, Param


def _apply(cfg, axis, torque_rms_Nm, corner_hz):
    p = cfg.platform[axis]
    p.disturbance_torque_rms_Nm, p.disturbance_corner_hz = torque_rms_Nm, corner_hz
    return cfg


EFFECT = Effect(
    "platform_disturbance",
    __doc__.strip().splitlines()[0],
    (
        Param("torque_rms_Nm", 1e-3, 1e-6, 0.1, log=True),
        Param("corner_hz", 5.0, 0.1, 100.0, log=True),
    ),
    _apply,
    key_param="torque_rms_Nm",
)
