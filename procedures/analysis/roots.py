"""Closed-loop roots of a stabilization loop from its identified parts (thesis Ch. III H,
Tables 5 and 6, Figs. 25 and 28).

The thesis read the closed-loop roots off root loci of its model: Table 5 for Mode 3
(autocollimator stabilization), Table 6 for the gyro modes 4 and 5. Here the loop is closed
over parts measured in the same run:

* the compensation network C(s), eq. 3.28, fitted inside the excited loop (the excitation's
  ``network_in_loop``: the quiet record's H1 is biased at the lowest frequencies by the
  network's 6.7 s pole);
* the gimbal axis, amplifier input -> angle, P(s) = Kp Km / ((La s + Ra)(J s^2 + D s + k)
  + Km Kb s) (eqs. 3.23-3.27), with J, D and k fitted to the excited record;
* the loop's sensor: in Mode 3 the control channel, K_ac F(s) (F its 2nd-order filter,
  eq. 3.21); in modes 4 and 5 the axis gyro's pickoff, whose float the autocollimator cages
  through the PI caging amplifier (II C.1.a(8)-(9), Fig. 27). With sigma' = theta' - sigma / tau
  + (K_ac F / K_g)(2 zeta_c w_c + w_c^2 / s) theta (the amplifier's gains designed for the
  loop's w_c and zeta_c), the pickoff per angle is
  S(s) = [K_g s^2 + K_ac F(s) (2 zeta_c w_c s + w_c^2)] / (s (s + 1/tau)).
  Leaving the caging out moves c1 by up to 4.4 % (Y, drawn rigs). The pickoff's K_g is the
  stopwatch's where a campaign has measured it (``pickoff``), else it is measured as the ratio
  of the sensor to the instrumentation channel through V_Td (so a wrong data-sheet K_g shows),
  with ``IN_LOOP_GAIN_ALLOWANCE`` for the coupling below.

The loop is the axis's alone, as Tables 5 and 6 close it. In modes 4 and 5 the gyro's viscous
cross-axis coupling (II C.4.d) ties the X and Y loops through the X-Y gyro at the loops' own
frequencies; no part here carries it. The coupled rig's poles (``simhw.plant.linearized_poles``
without an axis) differ from the loop alone's: its X pair's natural frequency by a median
1.1 % and up to 7.6 % on 40 drawn rigs, most where the X and Y pairs are close.
Inside the loop the coupling reaches the pickoff, so a gain measured there is not the loop
alone's: it read -1.25 .. +1.70 % off K_g on 12 drawn linear rigs, and put the platform pair
0.4-0.6 % off, outside its interval on 4 of them (issue 38).

With C = -g N_c / D_c (negative feedback) the loop gain is L = -C P S, and the closed-loop roots
are the zeros of 1 + L, i.e. of the polynomial D_c D_p D_s + g N_c N_p N_s. The polynomials are
built in s / ``W_SCALE`` (the roots span 0.15 to 5000 rad/s; the scaled coefficients stay
within a few decades of each other for the ninth degree this is). The rational forms of
DESIGN.md section 9 fail after discretization; these are continuous-time and exact.

Why not fit a rational function to the measured sensitivity pa / (K_d V_Td) = 1 / (1 + L)
directly? Its poles are the closed-loop roots, but the real roots c1 and c4 sit beside the
open loop's poles (its zeros) and show only as a 2 dB step each; Sanathanan-Koerner fits of
simulated runs put c4 at 84 rad/s for 126 in Mode 3, and found no c4 in Mode 4. The
sensitivity is instead the check: the closed model's 1 / (1 + L) is set against the measured
one, bin by bin, in units of each bin's standard error.

Naming: the *platform pair* is the complex pair of least damping with |p| in the band; ``c1``
the real root below it and ``c4`` the real root above it nearest to it (Tables 5 and 6).

Intervals: each part's fit is repeated on each leave-one-out block of the excited record (the
network, the platform and the sensor ratio all leave out the same block b, so what they share
is carried along); the loop is closed
for each, each named root matched to the nearest root, and the delete-one jackknife gives
the standard error of its natural frequency and damping (Student's t, ``n_blocks - 1`` dof).
What the blocks share is not in that scatter: the sensor gain's uncertainty beyond its
replicates (the stopwatch's interval, or ``IN_LOOP_GAIN_ALLOWANCE``) is, as each root's move
when the gain moves by it, added in quadrature (``close_loop``).

References
----------
.. [Klinger] R. Klinger, 1974, Ch. III G-H (eqs. 3.21-3.28, Tables 5 and 6), Ch. V C-D.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.polynomial import Polynomial

from drivers.rig_datasheet import AutocollimatorConstants, PlatformConstants
from procedures.analysis.intervals import Estimate, from_stderr, judged, through_scale, widened
from procedures.analysis.transfer import (
    SE_FLOOR,
    Response,
    TransferError,
    jackknife_se,
    network_response,
    platform_response,
    sensor_filter,
    sensor_scale_V_per_rad,
    smoothed,
    usable,
)

#: how far the pickoff's gain measured inside a gyro-mode loop may lie from the loop alone's,
#: relative, 95 %: the cross-axis coupling (module docstring) reads in the pickoff per angle as
#: S / (1 + (c_a c_b / h^2) S_other), S_other the other loop's sensitivity: 1.000 up to 1 Hz,
#: 0.965-1.023 (to -2.9 deg) at 5-15 Hz, and the gain fitted over 0.3-50 Hz 1.25-1.7 % off
#: K_g, on drawn rigs
IN_LOOP_GAIN_ALLOWANCE = 0.02

#: the polynomials' variable is s / W_SCALE (rad/s)
W_SCALE = 100.0
_S = Polynomial([0.0, W_SCALE])  # s in the scaled variable


def _lag(w: float) -> Polynomial:
    """s / w + 1."""
    return _S / w + 1.0


def network_poly(p: Mapping[str, float]) -> tuple[float, Polynomial, Polynomial]:
    """Eq. 3.28 as (g, N_c, D_c): C(s) = -g N_c / D_c."""
    num = _lag(p["w2_rad_per_s"]) * _lag(p["w3_rad_per_s"])
    den = (
        _lag(p["w1_rad_per_s"])
        * _lag(p["w4_rad_per_s"])
        * _lag(p["w5_rad_per_s"])
        * _lag(p["w6_rad_per_s"])
    )
    return float(p["gain"]), num, den


def platform_poly(
    J: float, D: float, k: float, pc: PlatformConstants
) -> tuple[Polynomial, Polynomial]:
    """Amplifier input -> angle (rad/V), eqs. 3.23-3.27: Kp Km / ((La s + Ra)(J s^2 + D s + k) + Km Kb s)."""
    num = Polynomial([pc.amp_gain * pc.motor_Nm_per_A])
    den = (pc.armature_H * _S + pc.armature_ohm) * (
        J * _S * _S + D * _S + k
    ) + pc.motor_Nm_per_A * pc.back_emf_V_s * _S
    return num, den


@dataclass(frozen=True)
class GyroCaging:
    """The float's restraint and its caging through the autocollimator (modes 4 and 5)."""

    natural_rad_per_s: float
    zeta: float
    restraint_s: float


def sensor_poly(
    kind: str, gain_V_per_rad: float, ac: AutocollimatorConstants, caging: GyroCaging | None = None
) -> tuple[Polynomial, Polynomial]:
    """The loop's sensor as N_s / D_s (module docstring): the control channel's 2nd-order
    filter (eq. 3.21), or the gyro pickoff with its float caged through the autocollimator."""
    w, z = ac.control_filter_rad_per_s, ac.control_filter_zeta
    filt_num, filt_den = Polynomial([w * w]), _S * _S + 2 * z * w * _S + w * w
    if kind == "ctl":
        return gain_V_per_rad * filt_num, filt_den
    if kind == "gyro":
        if caging is None:
            return Polynomial([gain_V_per_rad]), Polynomial([1.0])
        kac = sensor_scale_V_per_rad(ac, "ac_ctl")
        wc, zc = caging.natural_rad_per_s, caging.zeta
        num = gain_V_per_rad * _S * _S * filt_den + kac * filt_num * (2 * zc * wc * _S + wc * wc)
        return num, _S * (_S + 1.0 / caging.restraint_s) * filt_den
    raise ValueError(f"sensor kind {kind!r}: 'ctl' or 'gyro'")


def sensor_shape(
    f_hz: np.ndarray,
    kind: str,
    ac: AutocollimatorConstants,
    gain_V_per_rad: float = 1.0,
    caging: GyroCaging | None = None,
) -> np.ndarray:
    """The sensor's response per unit of ``gain_V_per_rad`` (the caging term does not scale)."""
    f = np.asarray(f_hz, float)
    if kind == "ctl" or caging is None:
        return sensor_filter(f, ac, "ac_ctl") if kind == "ctl" else np.ones(f.shape, complex)
    num, den = sensor_poly(kind, gain_V_per_rad, ac, caging)
    x = 2j * np.pi * f / W_SCALE
    return num(x) / den(x) / gain_V_per_rad


@dataclass(frozen=True)
class LoopParts:
    """One identification of the loop's parts (the full record's, or one leave-one-out's)."""

    network: Mapping[str, float]
    J: float
    D: float
    k: float
    sensor_V_per_rad: float
    caging: GyroCaging | None = None

    def roots(self, pc: PlatformConstants, ac: AutocollimatorConstants, kind: str) -> np.ndarray:
        """The zeros of 1 + L (rad/s): D_c D_p D_s + g N_c N_p N_s."""
        g, nc, dc = network_poly(self.network)
        np_, dp = platform_poly(self.J, self.D, self.k, pc)
        ns, ds = sensor_poly(kind, self.sensor_V_per_rad, ac, self.caging)
        char: Polynomial = dc * dp * ds + g * nc * np_ * ns
        return np.asarray(char.roots(), complex) * W_SCALE

    def sensitivity(
        self, f_hz: np.ndarray, pc: PlatformConstants, ac: AutocollimatorConstants, kind: str
    ) -> np.ndarray:
        """1 / (1 + L(j w)): the amplifier input per K_d V_Td."""
        p = platform_response(
            f_hz, self.J, self.D, self.k, pc, ac, "ac_inst"
        ) / sensor_scale_V_per_rad(ac, "ac_inst")
        p = p / sensor_filter(f_hz, ac, "ac_inst")  # amplifier input -> angle
        loop = (
            -network_response(f_hz, self.network)
            * p
            * self.sensor_V_per_rad
            * sensor_shape(f_hz, kind, ac, self.sensor_V_per_rad, self.caging)
        )
        return 1.0 / (1.0 + loop)


def sensor_gain(
    resp: Response,
    kind: str,
    ac: AutocollimatorConstants,
    lo_hz: float,
    hi_hz: float,
    caging: GyroCaging | None = None,
) -> tuple[float, list[float]]:
    """K_s (V/rad) from the sensor per instrumentation-channel response through V_Td, and its
    leave-one-out replicates: the weighted mean of ln|H / model shape| over the usable band (the
    caged pickoff's shape depends on K_g a little below 1 Hz: two passes)."""
    ok = usable(resp, lo_hz, hi_hz)
    if ok.sum() < 6:
        raise TransferError(
            f"{resp.source} -> {resp.target}: only {int(ok.sum())} bins in {lo_hz:g}-{hi_hz:g} Hz "
            f"with coherence >= 0.5; the sensor's gain needs 6"
        )
    f = resp.f[ok]
    inst = sensor_scale_V_per_rad(ac, "ac_inst") * sensor_filter(f, ac, "ac_inst")
    # a bin's weight from its neighbours' errors: 8 blocks give each bin's own error to +-25 %,
    # and weighting a bin by its own lucky error pulls the mean toward it
    w = 1.0 / np.maximum(smoothed(resp.log_se[ok]), SE_FLOOR) ** 2

    def fit(H: np.ndarray, shape: np.ndarray) -> float:
        return float(np.exp(np.sum(w * np.log(np.abs(H / shape))) / np.sum(w)))

    def gain(H: np.ndarray) -> float:
        k = fit(H, sensor_shape(f, kind, ac) / inst)  # the caging term left out, then put in
        for _ in range(2 if caging is not None else 0):
            k = fit(H, sensor_shape(f, kind, ac, k, caging) / inst)
        return k

    return gain(resp.H[ok]), [gain(Hb[ok]) for Hb in resp.H_blocks]


@dataclass(frozen=True)
class Root:
    """A named closed-loop root: natural frequency (rad/s) and damping (only for a pair)."""

    name: str
    pole: complex
    w: Estimate
    zeta: Estimate | None

    def values(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "w_rad_per_s": _r(self.w.value) if self.w.resolved else None,
            "w_rad_per_s_ci95": [_r(self.w.lo), _r(self.w.hi)],
            "pole": [_r(self.pole.real), _r(self.pole.imag)],
        }
        resolved = {"w_rad_per_s": self.w.resolved}
        if self.zeta is not None:
            out["zeta"] = _r(self.zeta.value) if self.zeta.resolved else None
            out["zeta_ci95"] = [_r(self.zeta.lo), _r(self.zeta.hi)]
            resolved["zeta"] = self.zeta.resolved
        out["resolved"] = resolved
        why = {
            k: e.why
            for k, e in (("w_rad_per_s", self.w), ("zeta", self.zeta))
            if e is not None and not e.resolved
        }
        if why:
            out["why_unresolved"] = why
        return out


def _r(v: float) -> float:
    return round(float(v), 5)


def name_roots(roots: np.ndarray, lo_w: float, hi_w: float) -> dict[str, complex]:
    """Table 5/6's roots by their place in the loop (module docstring)."""
    stable = roots[roots.real < 0]
    pairs = [p for p in stable if p.imag > 1e-9 * abs(p) and lo_w <= abs(p) <= hi_w]
    out: dict[str, complex] = {}
    if not pairs:
        return out
    pair = min(pairs, key=lambda p: -p.real / abs(p))
    out["platform_pair"] = complex(pair)
    real = [complex(p.real, 0.0) for p in stable if abs(p.imag) <= 1e-9 * abs(p)]
    below = [p for p in real if abs(p) < abs(pair)]
    above = [p for p in real if abs(p) > abs(pair)]
    if below:
        out["c1"] = max(below, key=abs)
    if above:
        out["c4"] = min(above, key=abs)
    return out


def _wz(p: complex) -> tuple[float, float]:
    return abs(p), -p.real / abs(p)


def _nearest_wz(root_sets: Sequence[np.ndarray], p: complex) -> np.ndarray:
    """(natural frequency, damping) of each set's root nearest ``p``, one row a set."""
    return np.array([_wz(rr[np.argmin(np.abs(rr - p))]) for rr in root_sets]).reshape(-1, 2)


@dataclass
class ClosedLoop:
    """The closed-loop roots of one axis's loop, named, with intervals, and the model's check
    against the measured sensitivity."""

    mode: int
    sensor: str
    roots: np.ndarray
    named: dict[str, Root]
    sensor_V_per_rad: Estimate
    #: the closed model's 1 / (1 + L) against the measured pa / (K_d V_Td), 0.3-50 Hz
    check_db_rms: float
    check_deg_rms: float
    check_normalized: float
    check_bins: int
    band_hz: tuple[float, float]
    notes: list[str] = field(default_factory=list)
    #: where the sensor's gain came from: "measured in the loop", or the stopwatch's K_g
    sensor_from: str = "measured in the loop"
    #: the pickoff's gain as measured inside the loop, where the loop used the stopwatch's
    sensor_in_loop_V_per_rad: Estimate | None = None

    def values(self) -> dict[str, Any]:
        s, q = self.sensor_V_per_rad, self.sensor_in_loop_V_per_rad
        check = (
            {
                "sensor_in_loop_mV_per_urad": _r(q.value * 1e-3),
                "sensor_in_loop_mV_per_urad_ci95": [_r(q.lo * 1e-3), _r(q.hi * 1e-3)],
            }
            if q is not None
            else {}
        )
        return {
            "mode": self.mode,
            "sensor": self.sensor,
            "roots": {k: r.values() for k, r in self.named.items()},
            "all_roots": [
                [_r(p.real), _r(p.imag)] for p in sorted(self.roots, key=abs) if p.imag >= 0
            ],
            "sensor_mV_per_urad": _r(s.value * 1e-3),
            "sensor_mV_per_urad_ci95": [_r(s.lo * 1e-3), _r(s.hi * 1e-3)],
            "sensor_from": self.sensor_from,
            **check,
            "check": {
                "band_hz": list(self.band_hz),
                "bins": self.check_bins,
                "db_rms": _r(self.check_db_rms),
                "deg_rms": _r(self.check_deg_rms),
                "normalized": _r(self.check_normalized),
            },
            **({"notes": list(self.notes)} if self.notes else {}),
        }


def close_loop(
    mode: int,
    parts: LoopParts,
    replicates: Sequence[LoopParts],
    pc: PlatformConstants,
    ac: AutocollimatorConstants,
    sensitivity: Response,
    band_hz: tuple[float, float],
    dof: int,
    sensor_replicates: Sequence[float],
    *,
    sensor_rel_half: float = 0.0,
    sensor_from: str = "measured in the loop",
    sensor_in_loop: Estimate | None = None,
) -> ClosedLoop:
    """Close the loop over ``parts`` and each of ``replicates`` (module docstring).

    ``sensor_rel_half``: how well the sensor's gain is known beyond its replicates' scatter,
    relative, 95 % (the stopwatch's interval, or ``IN_LOOP_GAIN_ALLOWANCE``); each root's
    interval carries the root's move when the gain moves by it, in quadrature."""
    kind = "ctl" if mode == 3 else "gyro"
    roots = parts.roots(pc, ac, kind)
    lo_w, hi_w = 2 * np.pi * band_hz[0], 2 * np.pi * band_hz[1]
    names = name_roots(roots, lo_w, hi_w)
    rep_roots = [r.roots(pc, ac, kind) for r in replicates]
    moved = [
        replace(parts, sensor_V_per_rad=parts.sensor_V_per_rad * (1.0 + u)).roots(pc, ac, kind)
        for u in ((-sensor_rel_half, sensor_rel_half) if sensor_rel_half > 0 else ())
    ]
    named: dict[str, Root] = {}
    for name, p in names.items():
        se = jackknife_se(_nearest_wz(rep_roots, p))
        w, z = _wz(p)
        a_w, a_z = np.max(np.abs(_nearest_wz(moved, p) - (w, z)), axis=0) if moved else (0.0, 0.0)
        named[name] = Root(
            name,
            p,
            widened(from_stderr(w, float(se[0]), dof=dof), float(a_w)),
            widened(from_stderr(z, float(se[1]), dof=dof), float(a_z)) if abs(p.imag) > 0 else None,
        )
    sensor = sensor_estimate(parts.sensor_V_per_rad, sensor_replicates, dof, sensor_rel_half)
    # the check: the closed model against the measured sensitivity
    ok = usable(sensitivity, *band_hz)
    f = sensitivity.f[ok]
    q = np.log(parts.sensitivity(f, pc, ac, kind) / (sensitivity.H[ok] / pc.command_divider))
    db = float(np.sqrt(np.mean((q.real * 20 / np.log(10)) ** 2))) if f.size else float("nan")
    deg = float(np.degrees(np.sqrt(np.mean(q.imag**2)))) if f.size else float("nan")
    norm = (
        float(
            np.sqrt(
                np.mean(
                    np.concatenate(
                        [q.real / sensitivity.log_se[ok], q.imag / sensitivity.phase_se_rad[ok]]
                    )
                    ** 2
                )
            )
        )
        if f.size
        else float("nan")
    )
    notes = []
    missing = [k for k in ("platform_pair", "c1", "c4") if k not in named]
    if missing:
        notes.append(f"not found: {', '.join(missing)}")
    if np.any(roots.real >= 0):
        notes.append(
            "the closed model has a root in the right half-plane: the identified parts do not make a "
            "stable loop, yet the rig recorded steadily - a part is wrong"
        )
    if norm > 3:
        notes.append(
            f"the closed model misses the measured sensitivity by {norm:.3g} standard errors rms: the "
            f"loop is not the linear one of the parts (Dahl friction at this amplitude?)"
        )
    return ClosedLoop(
        mode,
        kind,
        roots,
        named,
        sensor,
        db,
        deg,
        norm,
        int(ok.sum()),
        band_hz,
        notes,
        sensor_from,
        sensor_in_loop,
    )


def sensor_estimate(
    gain: float, replicates: Sequence[float], dof: int, rel_half: float = 0.0
) -> Estimate:
    """A sensor gain with its interval: its leave-one-out replicates' jackknife (Student's t)
    and ``rel_half`` (relative, 95 %: what the replicates do not carry) in quadrature; with
    replicates that do not scatter (a gain from outside the run), ``rel_half`` alone."""
    se = float(jackknife_se(np.asarray(replicates)))
    if se > 0:
        return through_scale(from_stderr(gain, se, dof=dof), rel_half)
    return judged(gain, gain * (1.0 - rel_half), gain * (1.0 + rel_half))
