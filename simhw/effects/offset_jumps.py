"""``offset_jumps``: square-wave offsets in the autocollimator (Ch. II B.10).

Two oscillators locking and slipping made the noncontrolling instrument's offset jump like a
square wave of about 20 arcsec (100 urad) every 40-400 s. Jumps of +-``amplitude_urad`` at
Poisson times of mean interval ``interval_s``.
"""

import math

import numpy as np

from simhw.effects import Effect, Param, primary_autocollimator


def _apply(cfg, axis, amplitude_urad, interval_s):
    ac = primary_autocollimator(cfg, axis, "offset_jumps")
    ac.offset_jump_urad, ac.offset_jump_interval_s = amplitude_urad, interval_s
    return cfg


def _guess(evidence) -> list[dict[str, float]]:
    # Spectra see only amplitude^2 / interval, so both come from the steps seen in the time
    # domain (the fit holds them; the spectra then score the candidate).
    # Each jump is a swing of 2 x amplitude (+a to -a).
    steps = sorted(abs(s) for s in evidence.steps_urad)
    if not steps:
        return []
    amp = steps[len(steps) // 2] / 2
    interval = evidence.duration_s / len(steps)
    return [
        {"amplitude_urad": min(max(amp, 0.2), 200.0), "interval_s": min(max(interval, 5.0), 1000.0)}
    ]


#: The size of a step is read through the model's step response (``gap.steps.template_gain``):
#: an error of the loop model of a few per cent is an error of the size, whatever the scatter
#: (measured on the test suite's independent generator: +0.2 to +2.7 %).
TEMPLATE_SYSTEMATIC = 0.03


def _spread(evidence, params: dict[str, float]) -> dict[str, float]:
    # the median's standard error from the steps' robust scatter (1.2533 x MAD-sigma / sqrt n),
    # with the template's systematic in quadrature; a swing is 2 x amplitude
    steps = np.abs(np.asarray(evidence.steps_urad, float)) / 2
    if len(steps) < 2:
        return {}
    mad = 1.4826 * float(np.median(np.abs(steps - np.median(steps))))
    stat = 1.2533 * mad / math.sqrt(len(steps))
    return {"amplitude_urad": math.hypot(stat, TEMPLATE_SYSTEMATIC * params["amplitude_urad"])}


EFFECT = Effect(
    "offset_jumps",
    __doc__.strip().splitlines()[0],
    (
        Param("amplitude_urad", 5.0, 0.2, 200.0, log=True),
        Param("interval_s", 60.0, 5.0, 1000.0, log=True),
    ),
    _apply,
    key_param="amplitude_urad",
    fit=(),
    guess=_guess,
    spread=_spread,
)
