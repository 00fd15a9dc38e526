"""``extra_damping``: viscous damping on the gimbal beyond the gyros' (Ch. V F: the viscous
bearing model the thesis tried first)."""

from simhw.effects import Effect, Param


def _apply(cfg, axis, damping_Nms):
    cfg.platform[axis].extra_damping_Nms = damping_Nms
    return cfg


EFFECT = Effect(
    "extra_damping",
    __doc__.strip().splitlines()[0],
    (Param("damping_Nms", 2.0, 0.05, 50.0, log=True),),
    _apply,
    key_param="damping_Nms",
)
