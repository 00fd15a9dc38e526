"""The simulated rig's truth for ``fbs demo``'s report: what each figure the campaign measures
is on the rig that ran it, computed from the sim config at the conditions measured.

The demo, unlike the procedures, may read the sim config and run the simulator offline: only
to fill the report's "simulated truth" column. A truth is of one of three kinds:

- ``parameter``: the sim config's own number (K_TO, K_g, To, eta, the drifts ...);
- ``computed``: exact from the simulator's noise or plant model (the NEA of a channel through
  its filters, the white level, the pickoff's noise in a band);
- ``offline``: from an offline simulation of the same rig, mode and band, longer than the
  record (``OFFLINE_RECORDS`` times) with a seed of its own: the platform's true angle for the
  platform rms, the unexcited sensor for the part incoherent with an excitation;
- ``describing function``: amplitude-dependent figures of a Dahl bearing (the excitation's
  stiffness, the closed-loop roots under excitation): Dahl's sinusoidal describing function
  (eq. 5.12) at the amplitude of a sinusoid of the test's rms. Under broadband motion a Dahl
  bearing has no single stiffness (its equivalent stiffness falls at low frequency, as
  Coulomb friction does under dither), so these are approximations, said so in the report and
  kept out of the coverage count (``exact`` False).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if (
    TYPE_CHECKING
):  # numpy and the simulator load when a truth is computed (``fbs --version`` imports fbs.demo)
    import numpy as np

    from simhw.config import Autocollimator, SimConfig
    from simhw.simulator import Simulator

#: an offline simulation is this many times the record it stands for (its own estimate's
#: error then is half the record's, or less)
OFFLINE_RECORDS = 4
#: the NEA's band (Table 1)
NEA_BAND_HZ = (0.1, 100.0)


@dataclass(frozen=True)
class Truth:
    value: float | None
    kind: str  # "parameter" | "computed" | "offline" | "describing function"
    how: str = ""

    @property
    def exact(self) -> bool:
        """Counted in the coverage: not an approximation of an ill-defined figure."""
        return self.value is not None and self.kind != "describing function"


def param(value: float | None, how: str = "sim config") -> Truth:
    return Truth(None if value is None else float(value), "parameter", how)


# ---------------------------------------------------------------------------- autocollimator
def _h2_ctl(ac: Autocollimator, f: np.ndarray) -> np.ndarray:
    import numpy as np

    s = 2j * math.pi * f
    w, z = ac.control_filter_rad_per_s, ac.control_filter_zeta
    return np.abs(w * w / (s * s + 2 * z * w * s + w * w)) ** 2


def _h2_inst(ac: Autocollimator, f: np.ndarray) -> np.ndarray:
    import numpy as np

    s = 2j * math.pi * f
    w1, w2, z = ac.inst_filter1_rad_per_s, ac.inst_filter2_rad_per_s, ac.inst_filter2_zeta
    return np.abs(1.0 / (s / w1 + 1.0) * w2 * w2 / (s * s + 2 * z * w2 * s + w2 * w2)) ** 2


def ac_white_level(ac: Autocollimator) -> float:
    """The angle noise's white level W (rad^2/Hz, one-sided) the simulator makes."""
    from simhw.simulator import ac_white_psd

    return ac_white_psd(
        ac.nea_urad,
        ac.flicker_corner_hz,
        ac.control_filter_rad_per_s,
        ac.control_filter_zeta,
        knee=ac.flicker_knee,
        slope=ac.flicker_slope,
    )


def ac_noise_psd(ac: Autocollimator, f: np.ndarray) -> np.ndarray:
    """The angle noise's PSD (rad^2/Hz): W K(f), plus an old config's excess 1/f W fx/f."""
    from simhw.simulator import ac_knee

    w = ac_white_level(ac)
    return w * (
        ac_knee(f, ac.flicker_corner_hz, ac.flicker_knee, ac.flicker_slope)
        + ac.extra_flicker_corner_hz / f
    )


def ac_nea_urad(ac: Autocollimator, channel: str) -> float:
    """The NEA (urad rms, 0.1-100 Hz) of the control or instrumentation channel: the noise's
    PSD through the channel's filter (eqs. 3.21-3.22), integrated."""
    import numpy as np

    f = np.geomspace(*NEA_BAND_HZ, 8000)
    h2 = _h2_ctl(ac, f) if channel == "ctl" else _h2_inst(ac, f)
    return float(math.sqrt(np.trapezoid(ac_noise_psd(ac, f) * h2, f)) * 1e6)


def baseline_truths(cfg: SimConfig, axis: str) -> dict[str, dict[str, Truth]]:
    """The open-loop baseline's figures (Ch. V B) on this rig, per key and channel."""
    from simhw.simulator import pickoff_white_psd

    ac, g = cfg.autocollimator[axis], cfg.gyro[axis]
    extra = " with its excess 1/f" if ac.extra_flicker_corner_hz else ""
    white = math.sqrt(ac_white_level(ac)) * 1e6
    pw = pickoff_white_psd(g.pickoff_noise_rms_urad, g.pickoff_lines) * 1e12
    in_band = [a for f, a in g.pickoff_lines if 1.0 <= f <= 50.0]
    drift = {
        band: drift_on_the_float_urad2(cfg, axis, *band) for band in ((1.0, 50.0), (0.1, 200.0))
    }
    return {
        "nea_urad": {
            "ctl": Truth(
                ac_nea_urad(ac, "ctl"), "computed", "W K(f) through the control filter" + extra
            ),
            "inst": Truth(
                ac_nea_urad(ac, "inst"),
                "computed",
                "W K(f) through the instrumentation filters (eq. 3.22)" + extra,
            ),
            "z": param(cfg.azimuth.nea_urad, "sim config (pure 1/f, no filter)"),
        },
        "white_urad_per_rtHz": {
            ch: Truth(white, "computed", "sqrt(W), the white level the simulator makes")
            for ch in ("ctl", "inst")
        },
        "flicker_corner_hz": {ch: param(ac.flicker_corner_hz) for ch in ("ctl", "inst")},
        "pickoff_rms_urad": {
            "1-50 Hz": Truth(
                math.sqrt(pw * 49.0 + sum(a * a / 2 for a in in_band) + drift[(1.0, 50.0)]),
                "computed",
                "the pickoff's white level over 1-50 Hz, its lines there and the gyro's random "
                "drift on the float",
            ),
            "0.1-200 Hz": Truth(
                math.sqrt(g.pickoff_noise_rms_urad**2 + drift[(0.1, 200.0)]),
                "computed",
                "the pickoff's noise (sim config) and the gyro's random drift on the float",
            ),
        },
    }


def drift_on_the_float_urad2(cfg: SimConfig, axis: str, lo_hz: float, hi_hz: float) -> float:
    """Variance (urad^2) in ``lo..hi`` Hz of the pickoff reading that the gyro's own random drift
    (angle random walk, bias instability, rate random walk) makes: in the baseline's record the
    gyros spin, caged, on the clamped platform (Ch. V B), so the float integrates the drift rate,
    sigma' = omega_d - sigma / (h/k) (II C.1.a) with the X-Y pair's viscous coupling (II C.4.d),
    under a caging loop of 0.1 rad/s. It is the gyro's signal, not the pickoff's electrical
    noise, but the pickoff shows it: on a drawn rig with an ARW of 0.5 urad/sqrt(s) it was 91 %
    on top of the pickoff noise's power at 1-2 Hz, 1.6 % of the 1-50 Hz rms.
    The plant's response from the drift input to the pickoff (state space, solved per
    frequency) times the drift's PSD, integrated on a log grid."""
    import numpy as np

    from simhw.plant import URAD, RelayState, build_plant
    from simhw.sampling import internal_rate
    from simhw.simulator import Sources

    f = np.geomspace(lo_hz, hi_hz, 4000)
    plant = build_plant(cfg, RelayState(mode=3, clamped=True))
    j = plant.inputs.index(f"wrand_{axis}")
    o = plant.outputs.index(f"gyro_{axis.lower()}")
    n = plant.A.shape[0]
    resolvent = 2j * np.pi * f[:, None, None] * np.eye(n) - plant.A
    x = np.linalg.solve(resolvent, np.broadcast_to(plant.B[:, j], (len(f), n))[..., None])[..., 0]
    volts = x @ plant.C[o] + plant.D[o, j]
    kg_V_per_rad = cfg.gyro[axis].pickoff_scale_mV_per_urad * 1e-3 / URAD
    # the drift's spectrum as the simulator's 1 kHz record holds it (its internal step)
    sources = Sources(cfg, 0, internal_rate(cfg.sampling, 1000.0)[1], spectral=True)
    rate_psd = sum(sources.spectrum(f"wrand_{axis}", f).values())
    return float(np.trapezoid(np.abs(volts / kg_V_per_rad) ** 2 * rate_psd, f)) / URAD**2


# ---------------------------------------------------------------------------- offline runs
@dataclass(frozen=True)
class OfflineRun:
    """Band rms (urad) from an offline simulation: ``theta`` the platform's true angle per axis,
    ``gyro`` the gyro channel's reading (pickoff noise and platform) per axis."""

    mode: int
    seconds: float
    theta: dict[tuple[str, float, float], float]
    gyro: dict[tuple[str, float, float], float]


def offline_band_rms(
    cfg: SimConfig,
    *,
    mode: int,
    seconds: float,
    rate_hz: float,
    seed: int,
    bands: Sequence[tuple[float, float]],
    axes: Sequence[str] = ("X", "Y"),
    seg_s: float = 16.0,
) -> OfflineRun:
    """Simulate ``seconds`` of the rig in ``mode`` offline (no drivers, virtual time) with the
    true platform angles, and give the rms of each axis's true angle and gyro reading in each
    band (Welch PSD, ``seg_s`` segments, Hann)."""
    import numpy as np
    import scipy.signal

    from daq.spectral import band_rms
    from simhw.simulator import Simulator

    chans = [c for a in axes for c in (f"ac_{a.lower()}_ctl", f"gyro_{a.lower()}")]
    sim = Simulator(cfg, rate_hz=rate_hz, seed=seed, mode=mode, truth=True, channels=chans)
    theta: dict[str, list[np.ndarray]] = {a: [] for a in axes}
    gyro: dict[str, list[np.ndarray]] = {a: [] for a in axes}
    for block in sim.run(seconds, 20.0):
        for a in axes:
            theta[a].append(np.asarray(block[f"theta_{a.lower()}"]) * 1e6)
            gyro[a].append(
                np.asarray(block[f"gyro_{a.lower()}"])
                / (cfg.gyro[a].pickoff_scale_mV_per_urad * 1e-3)
            )
    nper = int(round(seg_s * rate_hz))
    out_t: dict[tuple[str, float, float], float] = {}
    out_g: dict[tuple[str, float, float], float] = {}
    for a in axes:
        for store, series in ((out_t, theta[a]), (out_g, gyro[a])):
            x = np.concatenate(series)
            f, p = scipy.signal.welch(x, fs=rate_hz, nperseg=nper, detrend="linear")
            for lo, hi in bands:
                store[(a, lo, hi)] = band_rms(f, p, lo, hi)
    return OfflineRun(mode, seconds, out_t, out_g)


# ---------------------------------------------------------------------------- Dahl bearings
def dahl_at_amplitude(
    cfg: SimConfig, axis: str, rms_urad: float, w_rad_per_s: float
) -> tuple[float, float, str]:
    """The bearing's describing-function stiffness (N m/rad) and equivalent viscous damping
    (N m s, at ``w_rad_per_s``) at the amplitude of a sinusoid of ``rms_urad`` rms (eq. 5.12);
    for a linear bearing model its own constants. Returns (k, D, how)."""
    from procedures.analysis.dahl import describing_function
    from simhw.bearing import linear_part

    b = cfg.bearing[axis]
    if b.model != "dahl":
        lin = linear_part(b)
        return lin.stiffness_Nm_per_rad, lin.damping_Nms, f"the {b.model} bearing's own constants"
    k0 = b.eta_per_Nm * b.To_Nm**2
    amp = math.sqrt(2.0) * rms_urad * 1e-6
    df = complex(describing_function(b.eta_per_Nm * b.To_Nm * amp))
    return (
        k0 * df.real,
        k0 * df.imag / w_rad_per_s,
        f"Dahl's describing function (eq. 5.12) at {amp * 1e6:.3g} urad amplitude (a sinusoid of "
        f"{rms_urad:g} urad rms): {df.real:.4f} eta To^2",
    )


@dataclass(frozen=True)
class EquivalentLinear:
    """A Dahl bearing's equivalent linear stiffness and damping under an excitation run, from an
    offline simulation (``dahl_equivalent_linear``)."""

    stiffness_Nm_per_rad: float
    #: the bearing's equivalent damping with the gyro gimbals' (and any extra) viscous damping
    damping_Nms: float
    inertia_kg_m2: float
    motion_urad_rms: float
    how: str


def dahl_equivalent_linear(
    cfg: SimConfig,
    axis: str,
    level_V_rms: float,
    *,
    period_s: float = 16.0,
    update_hz: float = 250.0,
    band_hz: tuple[float, float] = (0.1, 60.0),
    signal_seed: int = 1,
    fit_hz: tuple[float, float] = (0.5, 50.0),
    periods: int = 25,
    rate_hz: float = 1000.0,
    seed: int = 97,
) -> EquivalentLinear:
    """What the excitation's platform fit measures on a Dahl bearing, exactly: the rig simulated
    offline in Mode 3 with the excitation's multisine as V_Td at ``level_V_rms`` (its noise
    included: the loop's jitter dithers the friction), the bearing's torque integrated along the
    true angle (eq. 5.3), its best linear approximation B = S_rT / S_r,theta at the excited lines
    (after the first period), and Z = J s^2 + (D_gyro + D_extra) s + B fitted as the procedure
    fits (``transfer.fit_impedance``, weights uniform).

    Dahl's sinusoidal describing function at the motion's rms (``dahl_at_amplitude``, eq. 5.12)
    is an approximation of it: under this broadband motion and the loop's noise the bearing's
    equivalent stiffness falls at low frequency and its damping goes as 1 / w, and on three rigs
    the describing function read k 2-7 % above this."""
    import numpy as np

    from procedures.analysis.dahl import dahl_torque
    from procedures.analysis.transfer import fit_impedance
    from procedures.calibrations.excitation import excitation_signal
    from simhw.simulator import Simulator

    a = axis.lower()
    b, pa = cfg.bearing[axis], cfg.platform[axis]
    if b.model != "dahl":
        raise ValueError(f"dahl_equivalent_linear: the {axis} bearing is {b.model!r}, not Dahl")
    sim = Simulator(cfg, rate_hz=rate_hz, seed=seed, mode=3, truth=True, channels=[f"cmd_{a}"])
    x = excitation_signal(
        int(round(period_s * update_hz)), update_hz, band_hz[0], band_hz[1], signal_seed
    )
    per = int(round(rate_hz / update_hz))
    # a period a block, each update a set-point event in it: the same samples, to the bit, as
    # a block per update (``Simulator.advance``), without 1,000 calls' overhead a period
    updates = [
        (i * per, functools.partial(_set_command, axis, float(v)))
        for i, v in enumerate(x * level_V_rms)
    ]
    theta, cmd = [], []
    for _ in range(periods):
        blk = sim.advance(len(updates) * per, updates, setpoints=True)
        theta.append(blk.truth[f"theta_{a}"])
        cmd.append(blk[f"cmd_{a}"])
    th, r = np.concatenate(theta), np.concatenate(cmd)
    torque = dahl_torque(th - th.mean(), b.To_Nm, b.eta_per_Nm)
    n = int(round(period_s * rate_hz))
    R, TH, T = (np.fft.rfft(v[n : periods * n].reshape(-1, n), axis=1) for v in (r, th, torque))
    f = np.fft.rfftfreq(n, 1.0 / rate_hz)
    sel = (f >= max(fit_hz[0], band_hz[0])) & (f <= min(fit_hz[1], band_hz[1]))
    B = np.sum(R.conj() * T, axis=0)[sel] / np.sum(R.conj() * TH, axis=0)[sel]
    s = 2j * np.pi * f[sel]
    J, D, k = fit_impedance(
        f[sel], pa.inertia_kg_m2 * s * s + (pa.gyro_damping_Nms + pa.extra_damping_Nms) * s + B
    )
    rms = float(np.std(th[n:])) * 1e6
    return EquivalentLinear(
        k,
        D,
        J,
        rms,
        f"the bearing's torque along the true angle of an offline run at {level_V_rms:.4g} "
        f"V rms ({rms:.3g} urad rms), its best linear approximation fitted over "
        f"{fit_hz[0]:g}-{fit_hz[1]:g} Hz",
    )


def _set_command(axis: str, volts: float, sim: Simulator) -> None:
    sim.set_command_torque_V(axis, volts)


def linearized_at_amplitude(
    cfg: SimConfig, mode: int, axis: str, rms_urad: float
) -> tuple[np.ndarray, str]:
    """The closed-loop poles of the rig linearized with the bearing replaced by its describing
    function at the amplitude (stiffness and, at the platform pair's frequency, the equivalent
    damping; two passes so that the damping is taken at the pair it moves)."""

    from simhw.plant import linearized_poles

    c = cfg.copy()
    w = math.sqrt(
        cfg.bearing[axis].eta_per_Nm
        * cfg.bearing[axis].To_Nm ** 2
        / cfg.platform[axis].inertia_kg_m2
    )
    how = ""
    poles = linearized_poles(cfg, mode, axis)
    for _ in range(2):
        k, d, how = dahl_at_amplitude(cfg, axis, rms_urad, w)
        c.bearing[axis].model = "spring"
        c.bearing[axis].stiffness_Nm_per_rad = k
        c.platform[axis].extra_damping_Nms = cfg.platform[axis].extra_damping_Nms + d
        poles = linearized_poles(c, mode, axis)
        pair = [p for p in poles if p.imag > 0 and 10.0 < abs(p) < 100.0]
        if not pair:
            break
        w = abs(min(pair, key=lambda p: abs(abs(p) - w)))
    return poles, how + f", its damping {d:.3g} N m s taken at the platform pair's {w:.3g} rad/s"


def in_interval(value: float | None, iv: Sequence[float | None] | None) -> bool | None:
    """Whether ``value`` lies in the closed interval ``iv`` (None where either is missing). An
    open end (null in a summary file, infinite in memory) bounds nothing there: the hysteresis's
    [0, inf) for a bearing without friction says the data bound nothing, and holds every truth
    by construction; it is no 95 % interval, so it is not counted (None) either."""
    if value is None or not iv or iv[0] is None or iv[1] is None:
        return None
    lo, hi = float(iv[0]), float(iv[1])
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return None
    return lo <= value <= hi


def binomial_tail(k: int, n: int, p: float = 0.05) -> float:
    """P(X >= k) for X ~ Binomial(n, p): how likely ``k`` or more misses of ``n`` 95 % intervals are."""
    return float(sum(math.comb(n, i) * p**i * (1 - p) ** (n - i) for i in range(k, n + 1)))


def max_misses(n: int, p: float = 0.05, alpha: float = 0.01) -> int:
    """The most misses of ``n`` independent 95 % intervals not rejected at level ``alpha``:
    the smallest k with P(X > k) <= alpha."""
    k = 0
    while binomial_tail(k + 1, n, p) > alpha:
        k += 1
    return k


def values_of(summary_values: Mapping[str, Any], key: str) -> dict[str, Any]:
    v = summary_values.get(key)
    return v if isinstance(v, dict) else {}
