"""``mount_resonance``: a flexible autocollimator mount (Ch. II B.9, III B).

The sensed angle is the gimbal angle through a lightly damped second-order mode, so the loop
sees a resonance the rigid model lacks (the thesis had to filter its control channel below
the mount's bending frequency).
"""

from . import Effect, Param, primary_autocollimator


def _apply(cfg, axis, freq_hz, damping):
    ac = primary_autocollimator(cfg, axis, "mount_resonance")
    ac.mount_freq_hz, ac.mount_damping = freq_hz, damping
    return cfg


EFFECT = Effect("mount_resonance", __doc__.strip().splitlines()[0],
                (Param("freq_hz", 60.0, 10.0, 300.0, log=True), Param("damping", 0.05, 0.005, 0.5, log=True)),
                _apply, key_param="freq_hz")
