"""``flicker_noise``: 1/f noise in the autocollimator angle beyond a nominal unit's (Ch. V B.3).

Air turbulence in the optical path adds 1/f noise; ``corner_hz`` is where the 1/f part meets
the sensor's white (shot-noise) level. It replaces the unit's own corner (its knee form and
slope stay the unit's, ``simhw.simulator.ac_knee``) and leaves the white level as it was: a
nominal unit's corner lies at 1.5-5 Hz (DESIGN.md section 8), so a corner of 8 Hz is this
effect. It enters the loop, like all sensor noise in Mode 3.
"""

import math

from simhw.effects import Effect, Param, primary_autocollimator
from simhw.simulator import ac_white_psd


def _apply(cfg, axis, corner_hz):
    ac = primary_autocollimator(cfg, axis, "flicker_noise")
    w, zeta = ac.control_filter_rad_per_s, ac.control_filter_zeta
    shape = {"knee": ac.flicker_knee, "slope": ac.flicker_slope}
    # The white level W stays: the data-sheet NEA (0.1-100 Hz) is W's with the unit's corner, so
    # the NEA follows the new corner (as procedures.analysis.gap.model.apply_nuisance moves it).
    white = ac_white_psd(ac.nea_urad, ac.flicker_corner_hz, w, zeta, **shape)
    moved = ac_white_psd(ac.nea_urad, corner_hz, w, zeta, **shape)
    ac.nea_urad *= math.sqrt(white / moved)
    ac.flicker_corner_hz = corner_hz
    return cfg


EFFECT = Effect(
    "flicker_noise",
    __doc__.strip().splitlines()[0],
    (
        Param(
            "corner_hz",
            10.0,
            5.0,
            100.0,
            log=True,
            doc="the 1/f corner (Hz) in place of the unit's; below 5 Hz is a nominal unit",
        ),
    ),
    _apply,
    key_param="corner_hz",
    owns=("ac_flicker",),
)
