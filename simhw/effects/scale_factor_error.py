"""``scale_factor_error``: the axis's sensors read ``1 + fraction`` times the nominal scale.

Applies to the primary autocollimator's control and instrumentation channels (or the
azimuth unit on Z): a calibration error, which also changes the loop gain.
"""

from simhw.effects import Effect, Param


def _apply(cfg, axis, fraction):
    k = 1.0 + fraction
    if axis in cfg.autocollimator:
        ac = cfg.autocollimator[axis]
        ac.control_scale_mV_per_urad *= k
        ac.inst_scale_mV_per_urad *= k
    else:
        cfg.azimuth.scale_mV_per_urad *= k
    return cfg


EFFECT = Effect(
    "scale_factor_error",
    __doc__.strip().splitlines()[0],
    (Param("fraction", 0.1, -0.5, 1.0),),
    _apply,
    key_param="fraction",
)
