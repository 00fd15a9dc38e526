"""``mount_resonance``: a flexible autocollimator mount (Ch. II B.9, III B).

The sensed angle is the gimbal angle through a lightly damped second-order mode, so the loop
sees a resonance the rigid model lacks (the thesis had to filter its control channel below
the mount's bending frequency). Floor motion shakes the mount as well as the loop does
(DESIGN.md section 8): ``excitation`` is the undisturbed mount's angle PSD at its frequency
from the floor alone, in units of the autocollimator's white angle PSD.
"""

from simhw.effects import Effect, Param, primary_autocollimator


def _apply(cfg, axis, freq_hz, damping, excitation):
    ac = primary_autocollimator(cfg, axis, "mount_resonance")
    ac.mount_freq_hz, ac.mount_damping, ac.mount_excitation = freq_hz, damping, excitation
    return cfg


def _guess(evidence) -> list[dict[str, float]]:
    # a lightly damped mode is narrow: start at each excess the comparison found, and at its
    # strongest shortfalls (inside the loop a mode reads as a notch in the sensor channels)
    # strongest shortfalls (inside the loop a mode reads as a notch in the sensor channels). A
    # peak may be the floor's doing or the loop's, a notch is the loop's: each excess is tried
    # with a strong and a weak floor excitation, each notch with a weak one.
    peaks = [f for f in evidence.peaks_hz[:4] if 10.0 <= f <= 300.0]
    dips = [f for f in evidence.dips_hz[:2] if 10.0 <= f <= 300.0]
    return [{"freq_hz": f, "excitation": e} for f in peaks for e in (10.0, 0.3)] + [
        {"freq_hz": f, "excitation": 0.3} for f in dips
    ]


EFFECT = Effect(
    "mount_resonance",
    __doc__.strip().splitlines()[0],
    (
        Param("freq_hz", 60.0, 10.0, 300.0, log=True),
        Param("damping", 0.05, 0.005, 0.5, log=True),
        Param(
            "excitation",
            10.0,
            0.1,
            1e4,
            log=True,
            limit="lo",
            doc="floor-driven peak PSD of the mount angle, in units of the sensor's white PSD "
            "(its lower bound is a mount the floor barely shakes: a physical limit)",
        ),
    ),
    _apply,
    key_param="freq_hz",
    guess=_guess,
)
