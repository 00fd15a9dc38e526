"""``gyro_cross_coupling``: stronger viscous cross-axis coupling in the gyro (II C.4.d).

Scales the float's viscous coupling c/h on the axis's gyro channel by ``factor``.
"""

from simhw.effects import Effect, Param


def _apply(cfg, axis, factor):
    ch = cfg.gyro[axis]
    ch.viscous_coupling_h_over_c = ch.viscous_coupling_h_over_c / factor
    return cfg


EFFECT = Effect(
    "gyro_cross_coupling",
    __doc__.strip().splitlines()[0],
    (Param("factor", 2.0, 0.1, 20.0, log=True),),
    _apply,
    key_param="factor",
)
