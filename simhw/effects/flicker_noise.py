"""``flicker_noise``: extra 1/f noise in the autocollimator angle (Ch. V B.3).

Air turbulence in the optical path adds 1/f noise; ``corner_hz`` is where it meets the
sensor's white (shot-noise) level. It enters the loop, like all sensor noise in Mode 3.
"""

from simhw.effects import Effect, Param, primary_autocollimator


def _apply(cfg, axis, corner_hz):
    primary_autocollimator(cfg, axis, "flicker_noise").extra_flicker_corner_hz = corner_hz
    return cfg


EFFECT = Effect("flicker_noise", __doc__.strip().splitlines()[0],
                (Param("corner_hz", 10.0, 0.5, 100.0, log=True),), _apply, key_param="corner_hz",
                owns=("ac_flicker",))
