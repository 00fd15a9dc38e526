"""The Fixed Base Simulator as one linear state-space model plus held nonlinear corrections.

``build_plant`` assembles the continuous-time model of the whole rig for one relay state
(mode, caging-inhibit switches, gyro wheel speed): three platform axes (inertia, gyro-gimbal
damping, bearing, gimbal motor with inductance and back-EMF, power amplifier, compensation
network), the two autocollimators with their filters, and four gyro channels with their
torquers and caging amplifiers. ``discretize`` turns it into an exact zero-order-hold model.

Nonlinear elements (power-amplifier clipping, torquer current limit, sensor linear ranges,
Dahl bearing friction, gimbal stops) are written as "linear part + correction": the linear
part lives in A, the correction ``f(z) - g z`` is computed by the kernel from the state at
the start of each step and held over it as an input. In normal operation every correction
but the Dahl residual is zero and the model is exact.

Sign conventions follow the thesis: a positive platform angle gives positive autocollimator
and gyro pickoff voltages; the compensation network output is inverted (negative feedback);
a positive command-torque voltage V_Td gives a positive torque; the pickoff rate is
sigma' = omega_i + omega_c + omega_d (Ch. II C.1.a(8)), so the caged torquer output voltage is
V_T = -(omega_i + omega_d) / KTO.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from drivers.rig_datasheet import ADC_CHANNELS
from simhw.bearing import linear_part
from simhw.config import AC_AXES, AXES, GYRO_CHANNELS, MODES, SimConfig

URAD = 1e-6
#: The gyro channel each platform axis is stabilized by in modes 4 and 5.
GYRO_FOR_AXIS = {"X": "X", "Y": "Y", "Z": "Z"}
#: The platform axis each gyro channel senses (the X-Z gyro's X is the redundant XRD).
AXIS_OF_CHANNEL = {"X": "X", "Y": "Y", "Z": "Z", "XRD": "X"}
#: Gyro pairs (a, b) with (a, b, spin) right-handed: X-Y gyro spins along +Z, X-Z along +Y.
GYRO_PAIRS = (("X", "Y"), ("Z", "XRD"))
#: Recorded channels of DESIGN.md section 5, in ADC order.
CHANNELS = ADC_CHANNELS  # what the simulated ADC offers: every channel of DESIGN.md section 5
TRUTH_CHANNELS = ("theta_x", "theta_y", "theta_z")
#: Caging-integrator reset time when the inhibit switch shorts the amplifier (Fig. 7).
CAGING_RESET_S = 0.05

# Nonlinearity kinds understood by the kernel.
NL_CLIP, NL_SOFTSAT, NL_DAHL, NL_STOP = 0, 1, 2, 3


class Lin(dict):
    """A linear combination of states and inputs: {('x'|'u', index): coefficient}."""

    def __add__(self, other: Lin) -> Lin:
        out = Lin(self)
        for k, v in other.items():
            out[k] = out.get(k, 0.0) + v
        return out

    def __mul__(self, g: float) -> Lin:
        return Lin({k: v * g for k, v in self.items()})

    __rmul__ = __mul__

    def __neg__(self) -> Lin:
        return self * -1.0

    def __sub__(self, other: Lin) -> Lin:
        return self + (-other)


@dataclass
class Nonlinearity:
    name: str
    kind: int
    z: Lin  # pre-signal (linear in x and u, may use earlier corrections)
    col: int  # input column the correction is written to (-1: none)
    p1: float = 0.0  # limit (clip, softsat, stop), To (dahl)
    p2: float = 0.0  # hard ceiling (softsat), eta (dahl)
    gain: float = 1.0  # slope of the linear part already in A: corr = f(z) - gain z
    state_theta: int = -1
    state_omega: int = -1


@dataclass
class Plant:
    """Continuous-time model x' = A x + B u, y = C x + D u, for one relay state."""

    states: list[str]
    inputs: list[str]
    outputs: list[str]
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    nonlinear: list[Nonlinearity]
    slow_inputs: list[str] = field(default_factory=list)


class _Builder:
    def __init__(self) -> None:
        self.states: list[str] = []
        self.inputs: list[str] = []
        self.deriv: dict[int, Lin] = {}
        self.outputs: dict[str, Lin] = {}
        self.nonlinear: list[Nonlinearity] = []

    def x(self, name: str) -> Lin:
        if name not in self.states:
            self.states.append(name)
        return Lin({("x", self.states.index(name)): 1.0})

    def u(self, name: str) -> Lin:
        if name not in self.inputs:
            self.inputs.append(name)
        return Lin({("u", self.inputs.index(name)): 1.0})

    def set_deriv(self, state: str, expr: Lin) -> None:
        self.x(state)
        self.deriv[self.states.index(state)] = expr

    def correction(
        self, name: str, kind: int, z: Lin, *, p1: float = 0.0, p2: float = 0.0, gain: float = 1.0
    ) -> Lin:
        """Register a nonlinearity; returns its correction input f(z) - gain z."""
        col = self.u(f"corr_{name}")
        self.nonlinear.append(
            Nonlinearity(name, kind, z, self.inputs.index(f"corr_{name}"), p1=p1, p2=p2, gain=gain)
        )
        return col

    def first_order(self, prefix: str, inp: Lin, w: float) -> Lin:
        """w/(s+w): y' = w (u - y)  (a low-pass, unity dc gain)."""
        y = self.x(prefix)
        self.set_deriv(prefix, (inp - y) * w)
        return y

    def second_order(self, prefix: str, inp: Lin, w: float, zeta: float) -> Lin:
        """w^2/(s^2 + 2 zeta w s + w^2) in (position, velocity) form (eqs. 3.21-3.22)."""
        q1, q2 = self.x(prefix + "_p"), self.x(prefix + "_v")
        self.set_deriv(prefix + "_p", q2)
        self.set_deriv(prefix + "_v", (inp - q1) * (w * w) - q2 * (2 * zeta * w))
        return q1

    def lead_lag(self, prefix: str, inp: Lin, z: float, p: float) -> Lin:
        """(s/z + 1)/(s/p + 1) = (p/z) [1 + (z - p)/(s + p)], well conditioned for any z, p."""
        q = self.x(prefix)
        self.set_deriv(prefix, inp - q * p)
        return (inp + q * (z - p)) * (p / z)

    def pade2(self, prefix: str, inp: Lin, delay: float) -> Lin:
        """Second-order Pade approximation of exp(-s T)."""
        z1, z2 = self.x(prefix + "_1"), self.x(prefix + "_2")
        self.set_deriv(prefix + "_1", z2)
        self.set_deriv(prefix + "_2", inp - z1 * (12 / delay**2) - z2 * (6 / delay))
        return inp + z2 * (-12 / delay)

    def build(self, slow_inputs: list[str]) -> Plant:
        nx, nu = len(self.states), len(self.inputs)
        out_names = list(self.outputs)
        ny = len(out_names)
        A, B = np.zeros((nx, nx)), np.zeros((nx, nu))
        C, D = np.zeros((ny, nx)), np.zeros((ny, nu))
        for row, expr in self.deriv.items():
            _scatter(expr, A[row], B[row])
        for i, name in enumerate(out_names):
            _scatter(self.outputs[name], C[i], D[i])
        missing = set(range(nx)) - set(self.deriv)
        if missing:
            raise RuntimeError(f"states without dynamics: {[self.states[i] for i in missing]}")
        return Plant(
            list(self.states),
            list(self.inputs),
            out_names,
            A,
            B,
            C,
            D,
            self.nonlinear,
            [s for s in slow_inputs if s in self.inputs],
        )


def _scatter(expr: Lin, xrow: np.ndarray, urow: np.ndarray) -> None:
    for (kind, idx), v in expr.items():
        (xrow if kind == "x" else urow)[idx] += v


@dataclass(frozen=True)
class RelayState:
    """What the mode relays and console switches select (DESIGN.md section 4)."""

    mode: int = 3
    caging_inhibit: tuple[bool, bool, bool, bool] = (False, False, False, False)
    spin: float = 1.0  # wheel speed as a fraction of operating speed
    #: platform clamped to the table, power-amplifier drive to the gimbal motors open (Ch. V B)
    clamped: bool = False

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(
                f"mode {self.mode} is not allowed (modes 0 and 7 are disallowed; use 1..6)"
            )
        if not 0.0 <= self.spin <= 1.0:
            raise ValueError(f"spin fraction {self.spin} outside 0..1")


def caging_gains(cfg: SimConfig, ch: str) -> tuple[float, float]:
    """Caging amplifier gains C1, C2 (V/V, 1/s) for the designed loop (Ch. II C.1.a(8)).

    omega_n = sqrt(K_T K_g C2), zeta = sqrt(K_T K_g C1^2 / 4 C2), K_T = 92.1 KTO KTC.
    A proportional-only amplifier (the redundant channel) gets C2 = 0 and a first-order loop
    of bandwidth omega_n.
    """
    g, p = cfg.gyro[ch], cfg.gyros
    kt = (
        p.sense_resistor_ohm
        * g.torquer_scale_urad_per_s_per_V
        * URAD
        * p.torquer_caging_mA_per_V
        * 1e-3
    )
    kg = g.pickoff_scale_mV_per_urad * 1e-3 / URAD
    wn, zeta = g.caging_natural_freq_rad_per_s, g.caging_zeta
    if g.caging_proportional_only:
        return wn / (kt * kg), 0.0
    return 2 * zeta * wn / (kt * kg), wn * wn / (kt * kg)


def torquer_limit_V(cfg: SimConfig, ch: str) -> float:
    """Torquer output voltage at the amplifier's maximum, 3.5 x earth rate (II C.1.a(1))."""
    g = cfg.gyro[ch]
    return (
        cfg.gyros.max_rate_earth_rates
        * cfg.site.earth_rate_rad_per_s
        / (g.torquer_scale_urad_per_s_per_V * URAD)
    )


SLOW_INPUTS = (
    [f"vtd_{a}" for a in AXES]
    + [f"gc_{a}" for a in AXES]
    + [f"vb_{c}" for c in GYRO_CHANNELS]
    + [f"wconst_{c}" for c in GYRO_CHANNELS]
)


def build_plant(cfg: SimConfig, relays: RelayState) -> Plant:
    """Assemble the continuous-time model of the rig for one relay state."""
    b = _Builder()
    mode = relays.mode
    optical_control = mode in (1, 2, 3)
    gyro_control = mode in (4, 5)
    pickoff = {}
    gamma = {}

    # --- Autocollimators (Table 1, eqs. 3.21-3.22) ---------------------------------------
    for a in AXES:
        b.x(f"theta_{a}")
        b.x(f"omega_{a}")
    for a in AC_AXES:
        ac = cfg.autocollimator[a]
        theta = b.x(f"theta_{a}")
        if ac.mount_freq_hz > 0:  # flexible mount: the sensed angle lags the gimbal (III B)
            theta = b.second_order(
                f"mount_{a}", theta, 2 * math.pi * ac.mount_freq_hz, ac.mount_damping
            )
            if ac.mount_excitation > 0:
                # floor motion shakes the mount too (DESIGN.md section 8): its angular
                # acceleration n drives the mode, th_b'' + 2 zeta w th_b' + w^2 th_b = w^2 th + n
                v = b.states.index(f"mount_{a}_v")
                b.deriv[v] = b.deriv[v] + b.u(f"nmount_{a}")
        seen = theta + b.u(f"nac_{a}")
        seen = seen + b.correction(
            f"ac_{a}",
            NL_SOFTSAT,
            seen,
            p1=ac.linear_range_urad * URAD,
            p2=1.2 * ac.linear_range_urad * URAD,
        )
        if ac.delay_s > 0:
            seen = b.pade2(f"delay_{a}", seen, ac.delay_s)
        ctl = b.second_order(
            f"acctl_{a}", seen, ac.control_filter_rad_per_s, ac.control_filter_zeta
        )
        gamma[a] = ctl * (ac.control_scale_mV_per_urad * 1e-3 / URAD) + b.u(f"gc_{a}")
        inst1 = b.first_order(f"acinst1_{a}", seen, ac.inst_filter1_rad_per_s)
        inst = b.second_order(
            f"acinst2_{a}", inst1, ac.inst_filter2_rad_per_s, ac.inst_filter2_zeta
        )
        b.outputs[f"ac_{a.lower()}_ctl"] = gamma[a]
        b.outputs[f"ac_{a.lower()}_inst"] = inst * (ac.inst_scale_mV_per_urad * 1e-3 / URAD)
    az = cfg.azimuth
    seen_z = b.x("theta_Z") + b.u("nac_Z")
    seen_z = seen_z + b.correction(
        "ac_Z",
        NL_SOFTSAT,
        seen_z,
        p1=az.linear_range_urad * URAD,
        p2=1.2 * az.linear_range_urad * URAD,
    )
    gamma["Z"] = seen_z * (az.scale_mV_per_urad * 1e-3 / URAD) + b.u("gc_Z")
    b.outputs["ac_z"] = gamma["Z"]

    # --- Gyros: pickoffs, torquers, caging amplifiers (II C.1.a, III A) -------------------
    gp = cfg.gyros
    bias_on = mode != 6
    for c in GYRO_CHANNELS:
        g = cfg.gyro[c]
        sigma = b.x(f"sigma_{c}")
        noisy = sigma + b.u(f"np_{c}")
        noisy = noisy + b.correction(
            f"pickoff_{c}",
            NL_SOFTSAT,
            noisy,
            p1=g.pickoff_linear_range_urad * URAD,
            p2=1.5 * g.pickoff_linear_range_urad * URAD,
        )
        pickoff[c] = noisy * (g.pickoff_scale_mV_per_urad * 1e-3 / URAD)
        b.outputs[f"gyro_{c.lower()}"] = pickoff[c]
    for c in GYRO_CHANNELS:
        g = cfg.gyro[c]
        c1, c2 = caging_gains(cfg, c)
        ax = AXIS_OF_CHANNEL[c]
        caged = (mode in (3, 4) or (mode == 5 and c != "Z")) and not relays.caging_inhibit[
            GYRO_CHANNELS.index(c)
        ]
        cage_in = (
            pickoff[c] if mode == 3 else -gamma[ax]
        )  # autocollimator supervision (II C.1.a(9))
        vint = b.x(f"cage_{c}")
        if caged:
            b.set_deriv(f"cage_{c}", cage_in if c2 != 0.0 else vint * (-1.0 / CAGING_RESET_S))
            vf = -(cage_in * c1) - vint * c2
        else:
            b.set_deriv(f"cage_{c}", vint * (-1.0 / CAGING_RESET_S))
            vf = Lin()
        current = vf * (gp.torquer_caging_mA_per_V * 1e-3)
        if bias_on:
            current = current + b.u(f"vb_{c}") * (gp.torquer_bias_mA_per_V * 1e-3)
        vt = current * gp.sense_resistor_ohm
        lim = torquer_limit_V(cfg, c)
        vt = vt + b.correction(f"torq_{c}", NL_CLIP, vt, p1=lim)
        b.outputs[f"torq_{c.lower()}"] = vt
        kto = g.torquer_scale_urad_per_s_per_V * URAD
        # sigma' = r (omega_i + omega_c + omega_d) - sigma / (h/k), before cross-axis coupling.
        drive = (
            b.x(f"omega_{ax}") + b.u(f"wconst_{c}") + b.u(f"wrand_{c}") + vt * kto
        ) * relays.spin
        b.deriv[b.states.index(f"sigma_{c}")] = drive - b.x(f"sigma_{c}") * (
            1.0 / g.restraint_time_s
        )
    for a_ch, b_ch in GYRO_PAIRS:
        # Viscous cross-axis coupling (II C.4.d): float drag c sigma' about one input axis
        # precesses the float about the other; with (a, b, spin) right-handed
        #   sigma_b' = f_b - (c_a/h) sigma_a',   sigma_a' = f_a + (c_b/h) sigma_b'.
        ka = relays.spin / cfg.gyro[a_ch].viscous_coupling_h_over_c
        kb = relays.spin / cfg.gyro[b_ch].viscous_coupling_h_over_c
        ia, ib = b.states.index(f"sigma_{a_ch}"), b.states.index(f"sigma_{b_ch}")
        fa, fb = b.deriv[ia], b.deriv[ib]
        sa = (fa + fb * kb) * (1.0 / (1.0 + ka * kb))
        b.deriv[ia] = sa
        b.deriv[ib] = fb - sa * ka

    # --- Platform axes: compensation, amplifier, motor, gimbal (III C-E, eq. 3.23-3.28) ---
    comp = cfg.compensation
    for a in AXES:
        p, br = cfg.platform[a], linear_part(cfg.bearing[a])
        if optical_control:
            err = gamma[a]
        elif gyro_control:
            err = pickoff[GYRO_FOR_AXIS[a]]
        else:  # mode 6: external compensation drives V_Td; the network input is open
            err = Lin()
        s1 = b.first_order(f"comp1_{a}", err, comp.w1_rad_per_s)
        s2 = b.lead_lag(f"comp2_{a}", s1, comp.w2_rad_per_s, comp.w4_rad_per_s)
        s3 = b.lead_lag(f"comp3_{a}", s2, comp.w3_rad_per_s, comp.w5_rad_per_s)
        vc = -b.first_order(f"comp4_{a}", s3, comp.w6_rad_per_s)  # eq. 3.28, inverted
        pa = vc + b.u(f"vtd_{a}") * p.command_divider  # eq. 3.27 (input side)
        b.outputs[f"pa_{a.lower()}"] = pa
        b.outputs[f"cmd_{a.lower()}"] = b.u(f"vtd_{a}") + b.u(f"gc_{a}")
        vp = pa * p.amp_gain
        vp = vp + b.correction(f"amp_{a}", NL_CLIP, vp, p1=p.amp_limit_V)
        if relays.clamped:
            # Ch. V B open loop: the drive to the motor is opened (the network and pa_* still
            # read), and the clamp holds the gimbal: no torque moves it, theta and omega stay
            # where the clamp caught them (the simulator zeroes omega as it engages)
            vp = Lin()
        theta, omega, cur = b.x(f"theta_{a}"), b.x(f"omega_{a}"), b.x(f"i_{a}")
        # eq. 3.25-3.26: La i' = V_p - Kb theta' - Ra i
        b.set_deriv(
            f"i_{a}", (vp - omega * p.back_emf_V_s - cur * p.armature_ohm) * (1.0 / p.armature_H)
        )
        damping = p.gyro_damping_Nms + p.extra_damping_Nms + br.damping_Nms
        torque = (
            cur * p.motor_torque_Nm_per_A
            - omega * damping
            - theta * br.stiffness_Nm_per_rad
            + b.u(f"md_{a}")
        )
        if br.dahl:
            bb = cfg.bearing[a]
            torque = torque + b.correction(
                f"dahl_{a}",
                NL_DAHL,
                theta,
                p1=bb.To_Nm,
                p2=bb.eta_per_Nm,
                gain=-br.stiffness_Nm_per_rad,
            )
        if relays.clamped:
            b.set_deriv(f"theta_{a}", Lin())
            b.set_deriv(f"omega_{a}", Lin())
        else:
            b.set_deriv(f"theta_{a}", omega)
            b.set_deriv(f"omega_{a}", torque * (1.0 / p.inertia_kg_m2))  # eq. 3.23
        b.nonlinear.append(
            Nonlinearity(
                f"stop_{a}",
                NL_STOP,
                theta,
                -1,
                p1=math.radians(p.stop_deg),
                state_theta=b.states.index(f"theta_{a}"),
                state_omega=b.states.index(f"omega_{a}"),
            )
        )
        b.outputs[f"theta_{a.lower()}"] = theta
    return b.build(SLOW_INPUTS)


@dataclass
class DiscretePlant:
    """Exact zero-order-hold discretization of a :class:`Plant` at step ``dt``."""

    plant: Plant
    dt: float
    Ad: np.ndarray
    Bd: np.ndarray


def discretize(plant: Plant, dt: float) -> DiscretePlant:
    """Ad = e^(A dt), Bd = int_0^dt e^(A s) ds B, from one matrix exponential (Van Loan)."""
    nx, nu = plant.B.shape
    M = np.zeros((nx + nu, nx + nu))
    M[:nx, :nx] = plant.A * dt
    M[:nx, nx:] = plant.B * dt
    E = scipy.linalg.expm(M)
    return DiscretePlant(plant, dt, E[:nx, :nx], E[:nx, nx:])


def linearized_poles(cfg: SimConfig, mode: int = 3, axis: str | None = None) -> np.ndarray:
    """Closed-loop poles (rad/s) of the rig linearized about rest (Dahl -> spring eta To^2).

    With ``axis``, that platform axis's stabilization loop alone, as Tables 5 and 6 close it:
    the states carrying the axis in their name, except the output-only instrumentation filter;
    in the optical modes also without the gyro channel and its caging amplifier, which the
    platform drives but which do not drive it. In modes 4 and 5 the gyro's float and its
    (autocollimator) caging loop are in the loop (Table 6), and the gyro's viscous cross-axis
    coupling (II C.4.d) is left out: it ties the X and Y loops through the X-Y gyro at the
    loops' own frequencies (the coupled rig's X pair, ``axis=None``, sits 0.5 % from the loop
    alone's on the thesis rig; on 40 drawn rigs its natural frequency by a median 1.1 % and up
    to 7.6 %, most where the X and Y pairs are close). Keeping the coupling's
    1 / (1 + c_x c_y / h^2) on the axis's float while leaving out the other loop, which undoes
    it at low frequency, would be neither (2 % off the pair both ways).
    """
    if axis is not None and mode in (4, 5):
        cfg = cfg.copy()
        for ch in cfg.gyro.values():
            ch.viscous_coupling_h_over_c = math.inf  # c / h = 0: no cross-axis drag
    plant = build_plant(cfg, RelayState(mode=mode))
    if axis is None:
        return np.linalg.eigvals(plant.A)
    gyro_loop = mode in (4, 5)
    keep = [
        i
        for i, s in enumerate(plant.states)
        if axis in s.split("_")[1:]
        and not s.startswith("acinst")
        and (gyro_loop or not s.startswith(("sigma_", "cage_")))
    ]
    return np.linalg.eigvals(plant.A[np.ix_(keep, keep)])
