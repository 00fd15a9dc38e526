"""``time_delay``: a pure delay in the autocollimator signal path (Pade, second order).

Slow electronics or digital filtering in the sensor path; it eats phase margin and moves the
closed-loop peak.
"""

from simhw.effects import Effect, Param, primary_autocollimator


def _apply(cfg, axis, delay_s):
    primary_autocollimator(cfg, axis, "time_delay").delay_s = delay_s
    return cfg


EFFECT = Effect(
    "time_delay",
    __doc__.strip().splitlines()[0],
    (Param("delay_s", 0.002, 1e-4, 0.02, log=True),),
    _apply,
    key_param="delay_s",
)
