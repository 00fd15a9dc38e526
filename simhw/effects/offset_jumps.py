"""``offset_jumps``: square-wave offsets in the autocollimator (Ch. II B.10).

Two oscillators locking and slipping made the noncontrolling instrument's offset jump like a
square wave of about 20 arcsec (100 urad) every 40-400 s. Jumps of +-``amplitude_urad`` at
Poisson times of mean interval ``interval_s``.
"""

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
    return [{"amplitude_urad": min(max(amp, 0.2), 200.0), "interval_s": min(max(interval, 5.0), 1000.0)}]


EFFECT = Effect("offset_jumps", __doc__.strip().splitlines()[0],
                (Param("amplitude_urad", 5.0, 0.2, 200.0, log=True),
                 Param("interval_s", 60.0, 5.0, 1000.0, log=True)),
                _apply, key_param="amplitude_urad", fit=(), guess=_guess)
