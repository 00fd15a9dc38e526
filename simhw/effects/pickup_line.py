"""``pickup_line``: electrical pickup, a sinusoid on a recorded channel (Ch. V D-E).

The thesis saw 200 Hz (the gyro spin-motor drive) in its autocollimator and compensation
signals. The line is added to the axis's autocollimator control channel as recorded; several
lines (mains and its harmonics) are several instances of the effect.
"""

from simhw.config import PickupLine
from simhw.effects import Effect, Param


def _apply(cfg, axis, freq_hz, amplitude_V):
    channel = f"ac_{axis.lower()}_ctl" if axis in ("X", "Y") else "ac_z"
    cfg.pickup.append(PickupLine(channel, freq_hz, amplitude_V))
    return cfg


def _guess(evidence) -> list[dict[str, float]]:
    # A line is narrower than a band of the spectra, which cannot place it inside the band: its
    # frequency is the one measured on the record at each narrow excess (``evidence.lines``),
    # held, and the spectra fit its amplitude.
    return [{"freq_hz": f} for f, _ in evidence.lines[:4] if 1.0 <= f <= 450.0]


def _spread(evidence, params: dict[str, float]) -> dict[str, float]:
    near = [(abs(f - params["freq_hz"]), s) for f, s in evidence.lines]
    return (
        {"freq_hz": min(near)[1]} if near and min(near)[0] < 1e-9 + 1e-6 * params["freq_hz"] else {}
    )


EFFECT = Effect(
    "pickup_line",
    __doc__.strip().splitlines()[0],
    (
        Param("freq_hz", 200.0, 1.0, 450.0, log=True),
        Param("amplitude_V", 0.003, 1e-4, 0.1, log=True),
    ),
    _apply,
    key_param="freq_hz",
    fit=("amplitude_V",),
    guess=_guess,
    spread=_spread,
    repeatable=True,
)
