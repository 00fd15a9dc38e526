"""``bearing_friction``: Dahl solid friction in the gimbal bearings (Ch. V F, eq. 5.2).

The thesis's central finding: for small motion the bearings act as a spring of stiffness
eta To^2, which puts a dip in the closed-loop autocollimator spectrum at the platform
resonance sqrt(k / I) / 2 pi (3.5 Hz on X). ``stiffness_Nm_per_rad`` and ``To_Nm`` fix eta.
Closed-loop spectra see the small-motion spring and the damping of the hysteresis, which
grows as k / To (procedures/analysis/gap/model.py ``linearized``): the gap workflow fits both, so its
To is the one that explains the dip's depth at the measured motion; the hysteresis sweep
(``fbs run hysteresis``) measures To and eta directly.
"""

from simhw.effects import Effect, Param


def _apply(cfg, axis, stiffness_Nm_per_rad, To_Nm, eta_per_Nm):
    b = cfg.bearing[axis]
    b.model = "dahl"
    b.To_Nm = To_Nm
    # The stiffness is the key parameter; eta follows from it (k = eta To^2).
    b.eta_per_Nm = stiffness_Nm_per_rad / To_Nm**2 if stiffness_Nm_per_rad > 0 else eta_per_Nm
    return cfg


def _derive(p: dict[str, float]) -> dict[str, float]:
    """The parameters as applied: eta follows from the stiffness and To."""
    if p["stiffness_Nm_per_rad"] > 0:
        p = p | {"eta_per_Nm": p["stiffness_Nm_per_rad"] / p["To_Nm"] ** 2}
    return p


EFFECT = Effect(
    "bearing_friction",
    __doc__.strip().splitlines()[0],
    (
        Param("stiffness_Nm_per_rad", 410.0, 50.0, 3000.0, log=True),
        # a large To is the loss-free spring limit (the hysteresis damping grows as k / To)
        Param("To_Nm", 0.016, 0.002, 0.1, log=True, limit="hi"),
        Param("eta_per_Nm", 1.6e6, 1e4, 1e8, log=True),
    ),
    _apply,
    key_param="stiffness_Nm_per_rad",
    fit=("stiffness_Nm_per_rad", "To_Nm"),
    derive=_derive,
)
