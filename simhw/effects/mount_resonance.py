"""``mount_resonance``: a flexible autocollimator mount (Ch. II B.9, III B).

The sensed angle is the gimbal angle through a lightly damped second-order mode, so the loop
sees a resonance the rigid model lacks (the thesis had to filter its control channel below
the mount's bending frequency).
"""

from simhw.effects import Effect, Param, primary_autocollimator


def _apply(cfg, axis, freq_hz, damping):
    ac = primary_autocollimator(cfg, axis, "mount_resonance")
    ac.mount_freq_hz, ac.mount_damping = freq_hz, damping
    return cfg


def _guess(evidence) -> list[dict[str, float]]:
    # a lightly damped mode is narrow: start at each excess the comparison found, and at its
    # strongest shortfalls (inside the loop a mode reads as a notch in the sensor channels)
    return [{"freq_hz": f} for f in evidence.peaks_hz[:4] + evidence.dips_hz[:2] if 10.0 <= f <= 300.0]


EFFECT = Effect("mount_resonance", __doc__.strip().splitlines()[0],
                (Param("freq_hz", 60.0, 10.0, 300.0, log=True), Param("damping", 0.05, 0.005, 0.5, log=True)),
                _apply, key_param="freq_hz", guess=_guess)
