"""The simulated Fixed Base Simulator: plant, noise, relays and recording chain, in blocks.

``Simulator.advance(n)`` returns the next ``n`` output samples of every recorded channel, as
the ADC would deliver them. Console-side settings (mode, caging inhibits, torquer biases,
command and autocollimator-bias voltages, table angles) take effect at the next block; drive
it in small blocks for fine timing. The physics is deterministic per seed and independent of
how a run is cut into blocks.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from simhw import geometry
from simhw.config import AC_AXES, AXES, GYRO_CHANNELS, SimConfig, validate
from simhw.kernel import CompiledPlant, half_steps
from simhw.noise import (
    ExcessFlickerNoise,
    FlickerNoise,
    LagNoise,
    Lines,
    RandomWalk,
    TelegraphJumps,
    WhiteNoise,
)
from simhw.plant import (
    CHANNELS,
    TRUTH_CHANNELS,
    URAD,
    Plant,
    RelayState,
    build_plant,
    discretize,
    torquer_limit_V,
)
from simhw.reduction import Kept, kept, reduce
from simhw.sampling import SamplingChain, internal_rate
from simhw.virtual_clock import VirtualClock

log = logging.getLogger(__name__)

#: Band in which Table 1 quotes the autocollimator noise-equivalent angle.
NEA_BAND_HZ = (0.1, 100.0)
#: Band in which the gyro pickoff noise rms is quoted (Ch. V, 0.1-200 Hz).
PICKOFF_BAND_HZ = (0.1, 200.0)
SPIN_READY = 0.99
#: an analog output beyond this is a diverged plant, not a signal (the amplifiers' supply is 28 V)
DIVERGED_V = 1e6


class SimulationDiverged(ValueError):
    """The plant's outputs left any physical range: the message says when, where and what."""


#: Wheel-speed resolution of the plant model during run-up and run-down.
SPIN_MODEL_STEP = 0.1


@dataclass
class Block:
    """``n`` samples of every channel from ``t0`` (s) at ``rate_hz``; volts as the ADC gives them."""

    t0: float
    rate_hz: float
    channels: tuple[str, ...]
    volts: np.ndarray  # (n, n_channels)
    overrange: np.ndarray  # (n, n_channels) bool
    truth: dict[str, np.ndarray] = field(default_factory=dict)

    def __getitem__(self, channel: str) -> np.ndarray:
        if channel in self.truth:
            return self.truth[channel]
        return self.volts[:, self.channels.index(channel)]

    def __len__(self) -> int:
        return len(self.volts)


def ac_knee(f: np.ndarray | float, corner_hz: float, knee: float, slope: float) -> np.ndarray:
    """The autocollimator angle noise's PSD over its white level W: with r = (fc/f)^slope,
    K(f) = knee (1 + r) + (1 - knee) max(1, r), fc = ``corner_hz``.

    Fig. 32 shows a white (shot-noise) floor with 1/f below about 3 Hz; how the two meet is
    the unit's: ``knee`` 1 adds them (1 + fc/f at slope 1, the thesis's reading), 0 is the
    sharp corner max(1, fc/f), and a nominal unit lies anywhere between, with a slope of
    0.8-1.2 (DESIGN.md section 8). The noise the simulator makes follows W K(f)
    (``simhw.noise.FlickerNoise`` realizes W (K - 1))."""
    f = np.asarray(f, float)
    r = (corner_hz / f) ** slope
    return knee * (1.0 + r) + (1.0 - knee) * np.maximum(1.0, r)


def ac_white_psd(
    nea_urad: float,
    corner_hz: float,
    w: float,
    zeta: float,
    *,
    knee: float = 1.0,
    slope: float = 1.0,
) -> float:
    """One-sided white PSD W (rad^2/Hz) of the autocollimator angle noise such that the control
    channel (second-order filter w, zeta; eq. 3.21) shows ``nea_urad`` rms in 0.1-100 Hz
    when the noise's PSD is W K(f) (``ac_knee``: a 1/f part of that slope meeting the white
    level at ``corner_hz`` with that knee; Table 1, Fig. 32)."""
    return (nea_urad * URAD) ** 2 / _nea_gain(
        float(corner_hz), float(w), float(zeta), float(knee), float(slope)
    )


@functools.lru_cache(maxsize=1024)
def _nea_gain(corner_hz: float, w: float, zeta: float, knee: float, slope: float) -> float:
    """The integral of K(f) |H_ctl(f)|^2 over the NEA band (``ac_white_psd``). Kept per shape:
    a model of the spectra builds the sources once per trial, and this integral over 4000
    points was over half of that."""
    f = np.geomspace(*NEA_BAND_HZ, 4000)
    s = 2j * math.pi * f
    h2 = np.abs(w * w / (s * s + 2 * zeta * w * s + w * w)) ** 2
    return float(np.trapezoid(ac_knee(f, corner_hz, knee, slope) * h2, f))


def pickoff_white_psd(rms_urad: float, lines: list) -> float:
    """White PSD (rad^2/Hz) that with the discrete lines makes ``rms_urad`` in 0.1-200 Hz."""
    var = (rms_urad * URAD) ** 2 - sum((a * URAD) ** 2 / 2 for _, a in lines)
    return max(var, 0.0) / (PICKOFF_BAND_HZ[1] - PICKOFF_BAND_HZ[0])


#: the largest seed (numpy takes any non-negative integer; this is a sane bound on a typo)
MAX_SEED = 2**63 - 1


def check_seed(seed: object, what: str | None = None) -> None:
    """Refuse a seed that is not a whole number 0..MAX_SEED, saying ``what`` was given (default
    ``seed <value>``) and the limit (numpy's own refusal, "expected non-negative integer", says
    neither)."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise ValueError(f"{what or f'seed {seed!r}'} must be a whole number 0..{MAX_SEED}")


class Sources:
    """All random inputs of the plant, one independent stream each."""

    def __init__(
        self, cfg: SimConfig, seed: int | tuple[int, int], dt: float, *, spectral: bool = False
    ) -> None:
        """``spectral``: for ``spectrum`` and ``lines`` only (a model of the spectra builds one
        per trial): every source shares one generator, so ``take`` refuses."""
        self.dt, self.spectral = dt, spectral
        #: samples of each input drawn ahead and not yet taken (``take``)
        self._ahead: dict[str, np.ndarray] = {}
        ss = np.random.SeedSequence(seed)
        names = (
            [f"nac_{a}" for a in AXES]
            + [f"np_{c}" for c in GYRO_CHANNELS]
            + [f"wrand_{c}" for c in GYRO_CHANNELS]
            + [f"md_{a}" for a in AXES]
        )
        shared = np.random.Generator(np.random.PCG64(0)) if spectral else None
        rngs = (
            {}
            if spectral
            else dict(
                zip(names, (np.random.Generator(np.random.PCG64(s)) for s in ss.spawn(len(names))))
            )
        )

        def sub(name: str) -> np.random.Generator:
            if shared is not None:
                return shared
            return np.random.Generator(np.random.PCG64(rngs[name].integers(2**63)))

        self.parts: dict[str, list] = {}
        # The X/Y common noise (Fig. 48): each axis draws it from its own generator seeded alike,
        # so both see the same sequence, each at its own pace (an input the reduced simulator
        # never reads costs nothing). Spawned after every other stream: a rig without it is
        # bit-identical to one from before it existed.
        common_seed = ss.spawn(1)[0]
        # Floor motion at each flexible mount: streams spawned after all of the above, so a rig
        # without it draws what it drew before it existed.
        mount_seeds = dict(zip(AC_AXES, ss.spawn(len(AC_AXES))))
        white_of = {}
        for a in AC_AXES:
            ac = cfg.autocollimator[a]
            fc = ac.flicker_corner_hz
            white = white_of[a] = ac_white_psd(
                ac.nea_urad,
                fc,
                ac.control_filter_rad_per_s,
                ac.control_filter_zeta,
                knee=ac.flicker_knee,
                slope=ac.flicker_slope,
            )
            frac = ac.common_noise_fraction
            # The unit's own 1/f, W (K - 1) (``ac_knee``); the bank reaches 10 x the corner (for
            # a high corner, the flicker_noise effect's) and at least the NEA band's top, over
            # which the white level W is set (``ac_white_psd``; issue 38: it stopped at 50 Hz).
            f_top = max(NEA_BAND_HZ[1], 10.0 * fc)
            self.parts[f"nac_{a}"] = [
                WhiteNoise(sub(f"nac_{a}"), white * (1.0 - frac), dt),
                FlickerNoise(
                    sub(f"nac_{a}"),
                    white * fc,
                    1e-4,
                    f_top,
                    dt,
                    corner_hz=fc,
                    knee=ac.flicker_knee,
                    slope=ac.flicker_slope,
                ),
                ExcessFlickerNoise(
                    sub(f"nac_{a}"), white * ac.extra_flicker_corner_hz, 1e-4, 50.0, dt
                ),
                TelegraphJumps(
                    sub(f"nac_{a}"), ac.offset_jump_urad * URAD, ac.offset_jump_interval_s, dt
                ),
            ]
            if frac > 0:
                common = shared or np.random.Generator(np.random.PCG64(common_seed))
                self.parts[f"nac_{a}"].append(WhiteNoise(common, white * frac, dt))
        az = cfg.azimuth
        level = (az.nea_urad * URAD) ** 2 / math.log(NEA_BAND_HZ[1] / NEA_BAND_HZ[0])
        self.parts["nac_Z"] = [FlickerNoise(sub("nac_Z"), level, 1e-4, 200.0, dt)]
        for c in GYRO_CHANNELS:
            g = cfg.gyro[c]
            lines = [(f, a * URAD) for f, a in g.pickoff_lines if f < 0.5 / dt]
            self.parts[f"np_{c}"] = [
                WhiteNoise(
                    sub(f"np_{c}"), pickoff_white_psd(g.pickoff_noise_rms_urad, g.pickoff_lines), dt
                ),
                Lines(sub(f"np_{c}"), lines, dt),
            ]
            # Random drift (IEEE 952 conventions, one-sided PSDs): white rate 2 N^2,
            # flicker B^2/(pi f), rate random walk K.
            self.parts[f"wrand_{c}"] = [
                WhiteNoise(sub(f"wrand_{c}"), 2 * (g.arw_urad_per_sqrt_s * URAD) ** 2, dt),
                FlickerNoise(
                    sub(f"wrand_{c}"),
                    (g.bias_instability_urad_per_s * URAD) ** 2 / math.pi,
                    1e-5,
                    1.0,
                    dt,
                ),
                RandomWalk(sub(f"wrand_{c}"), g.rrw_urad_per_s_per_sqrt_s * URAD, dt),
            ]
        for a in AXES:
            p = cfg.platform[a]
            # Optional platform disturbance torque (effect `platform_disturbance`).
            self.parts[f"md_{a}"] = [
                LagNoise(sub(f"md_{a}"), p.disturbance_torque_rms_Nm, p.disturbance_corner_hz, dt)
            ]
        for a in AC_AXES:
            # A flexible mount's floor excitation (angular acceleration, rad/s^2, white): the
            # mode th_b'' + 2 zeta w th_b' + w^2 th_b = w^2 th + n has |H(jw)|^2 = 1/(2 zeta w^2)^2
            # at w, so S_n = excitation W (2 zeta w^2)^2 puts excitation x W there (simhw.plant).
            ac = cfg.autocollimator[a]
            w = 2 * math.pi * ac.mount_freq_hz
            psd = (
                ac.mount_excitation * white_of[a] * (2 * ac.mount_damping * w * w) ** 2
                if w > 0
                else 0.0
            )
            self.parts[f"nmount_{a}"] = [
                WhiteNoise(shared or np.random.Generator(np.random.PCG64(mount_seeds[a])), psd, dt)
            ]

    #: Internal steps drawn ahead per input. Every part has its own stream and continues it
    #: exactly whatever the cut (``simhw.noise``), so drawing ahead changes no sample; it turns
    #: a sim rig's many short blocks (a set-point every 4 ms) into a few long draws.
    AHEAD = 4096

    def take(self, name: str, n: int) -> np.ndarray:
        if self.spectral:
            raise RuntimeError(
                "these Sources were made for spectra (spectral=True): they draw no streams"
            )
        buf = self._ahead.get(name)
        have = 0 if buf is None else len(buf)
        if have < n:
            m = max(n - have, self.AHEAD)
            fresh = np.zeros(m)
            for part in self.parts[name]:
                fresh += part.take(m)
            buf = fresh if buf is None or not have else np.concatenate([buf, fresh])
        assert buf is not None
        out, self._ahead[name] = buf[:n], buf[n:]
        return out

    def unread(self, name: str, samples: np.ndarray) -> None:
        """Put ``samples``, the last taken from input ``name`` and unused, back at the front of
        its stream: the next ``take`` gives them again."""
        if len(samples):
            buf = self._ahead.get(name)
            self._ahead[name] = (
                np.array(samples) if buf is None or not len(buf) else np.concatenate([samples, buf])
            )

    def initial(self, name: str) -> float:
        """The slowly varying part of input ``name`` at t = 0 (white noise and lines count 0)."""
        if name in self._ahead:
            raise RuntimeError(f"input {name!r} has been drawn from: its value at t = 0 is gone")
        return float(sum(getattr(part, "initial", lambda: 0.0)() for part in self.parts[name]))

    @property
    def names(self) -> list[str]:
        return list(self.parts)

    def spectrum(
        self, name: str, f: np.ndarray, cache: dict | None = None
    ) -> dict[str, np.ndarray]:
        """One-sided PSD (units^2/Hz) of input ``name`` as the plant's ZOH model sees it, by kind
        of source ("WhiteNoise", "FlickerNoise", ...), without deterministic lines: |H|^2 times
        their sum is the output's PSD (the model-gap workflow's expected spectra). With
        ``cache`` (a dict the caller keeps, for one frequency array), each source's spectrum is
        computed once per set of its parameters."""
        out: dict[str, np.ndarray] = {}
        for part in self.parts[name]:
            kind = type(part).__name__
            if cache is None:
                sp = part.spectrum(f, self.dt)
            else:
                key = part.spectrum_key() + (self.dt,)
                sp = cache.get(key)
                if sp is None:
                    sp = cache[key] = part.spectrum(f, self.dt)
            out[kind] = out.get(kind, 0.0) + sp
        return out

    def lines(self, name: str) -> list[tuple[float, float]]:
        """Deterministic sinusoids of input ``name``: (frequency Hz, amplitude)."""
        return [
            ln for part in self.parts[name] if hasattr(part, "lines") for ln in part.lines(self.dt)
        ]


class Simulator:
    """The simulated rig, from the relays to the ADC.

    Parameters
    ----------
    cfg : the rig's parameters (``SimConfig()`` is the thesis rig).
    rate_hz : output sample rate of the ADC.
    seed : one seed for every random source.
    mode : relay mode at start (DESIGN.md section 4).
    spin : gyro wheel speed at start as a fraction of operating speed; default "at speed"
        for modes 2-6 and "stopped" for mode 1. A run started in modes 3-5 with the wheels at
        speed starts in the caged steady state, as a rig that has been running for hours.
    truth : also return the true platform angles ``theta_x, theta_y, theta_z`` (rad).
    channels : the recorded channels to simulate (default: all of them, in ``CHANNELS`` order).
        A subset simulates only the part of the rig they depend on (``simhw.reduction``): the
        same numbers as the full rig gives on those channels, at a fraction of the cost (a
        single-axis record drops the other axes, their gyros and their noise).
    """

    def __init__(
        self,
        cfg: SimConfig | None = None,
        rate_hz: float = 1000.0,
        seed: int = 0,
        mode: int = 3,
        spin: float | None = None,
        truth: bool = False,
        clock: VirtualClock | None = None,
        channels: Sequence[str] | None = None,
    ) -> None:
        self.cfg = cfg = (cfg or SimConfig()).copy()
        validate(cfg)  # a config built in code has not been through from_dict's checks
        self.channels: tuple[str, ...] = CHANNELS if channels is None else tuple(channels)
        bad = [c for c in self.channels if c not in CHANNELS]
        if bad or not self.channels or len(set(self.channels)) != len(self.channels):
            raise ValueError(
                f"channels {list(self.channels)} must be distinct recorded channels, at least one "
                f"(the channels are {', '.join(CHANNELS)})"
            )
        #: the outputs the kernel computes, in the order of the columns it returns
        self._outputs = self.channels + (TRUTH_CHANNELS if truth else ())
        self._keep: Kept | None = None if channels is None else kept(cfg, self._outputs)
        # numpy's own refusal ("expected non-negative integer") names neither the value nor the limit
        check_seed(seed)
        self.seed = seed
        self.clock = clock or VirtualClock()
        self.truth = truth
        # per-block bookkeeping kept between blocks (``_table_geometry``, ``_layout``)
        self._geometry: tuple[tuple[float, ...], np.ndarray, np.ndarray] | None = None
        self._slow_layout: (
            tuple[Plant, tuple[float, ...], np.ndarray, list[tuple[int, int]]] | None
        ) = None
        self._last_layout: tuple[CompiledPlant, list[tuple[int, str]], list[int]] | None = None
        self._t_base = 0.0  # time of the last rate change
        self._rate_changes = 0
        self._set_timebase(rate_hz)
        self.relays = RelayState(
            mode=mode, spin=(1.0 if mode >= 2 else 0.0) if spin is None else spin
        )
        self._spin = self.relays.spin  # exact wheel speed; the relay state holds it rounded
        self.vtd = dict.fromkeys(AXES, 0.0)
        self.gamma_c = dict.fromkeys(AXES, 0.0)
        self.bias = dict.fromkeys(GYRO_CHANNELS, 0.0)
        for p in cfg.pickup:
            if p.channel not in CHANNELS:
                raise ValueError(
                    f"pickup channel {p.channel!r} is not a recorded channel ({', '.join(CHANNELS)})"
                )
        self._set_sampling()
        self._cache: dict[RelayState, CompiledPlant] = {}
        self._compiled = self._compile(self.relays)
        n_nl = len(self._compiled.nl_kind)
        self.nl_state = np.zeros((n_nl, 2))
        self.nl_state[:, 1] = np.nan
        self.x = np.zeros(len(self._compiled.disc.plant.states))
        #: the slow inputs (names, values) of the last chunk simulated (None before the first)
        self._last_slow: tuple[tuple[str, ...], np.ndarray] | None = None
        if self.relays.spin >= SPIN_READY and self.relays.mode in (3, 4, 5):
            self._settle()

    def _set_timebase(self, rate_hz: float) -> None:
        if not (rate_hz > 0 and math.isfinite(rate_hz)):
            raise ValueError(f"sample rate {rate_hz!r} Hz must be a positive number")
        s = self.cfg.sampling
        self.rate_hz = float(rate_hz)
        self.oversample, self.dt = internal_rate(s, self.rate_hz)
        self.step = 0  # internal steps since the last rate change

    def _set_sampling(self, ranges: dict[str, float] | None = None) -> None:
        """Noise sources, recording chain (with ``ranges`` kept) and pickup for the present step ``dt``."""
        s = self.cfg.sampling
        # Each time base gets its own streams, derived from the one seed.
        seed = self.seed if self._rate_changes == 0 else (self.seed, self._rate_changes)
        self.sources = Sources(self.cfg, seed, self.dt)
        self.chain = SamplingChain(
            self.channels,
            self.rate_hz,
            self.oversample,
            s.anti_alias_fraction,
            s.anti_alias_poles,
            s.adc_bits,
            s.default_range_V,
        )
        for c, r in (ranges or {}).items():
            self.chain.set_range(c, r)
        # Electrical pickup: phase zero at the start of the time base, on the plant's step count.
        self._pickup = [
            (
                self.channels.index(p.channel),
                Lines(None, [(p.freq_hz, p.amplitude_V)], self.dt, phase=0.0),
            )
            for p in self.cfg.pickup
            if p.channel in self.channels
        ]

    def set_rate(self, rate_hz: float) -> None:
        """Change the output sample rate now (the ADC was reconfigured).

        The physical state carries over; the plant is discretized for the new step, the noise
        generators restart from new streams of the same seed, and the anti-alias filter starts
        settled on the next input, as after a gap.
        """
        if float(rate_hz) == self.rate_hz:
            return
        t = self.time_s
        ranges = dict(self.chain.ranges)
        self._set_timebase(rate_hz)
        self._t_base = t
        self._rate_changes += 1
        self._set_sampling(ranges)
        self._cache.clear()
        self._compiled = self._compile(self.relays)

    # ------------------------------------------------------------------ console-side settings
    @property
    def mode(self) -> int:
        return self.relays.mode

    @property
    def time_s(self) -> float:
        return self._t_base + self.step * self.dt

    @property
    def spin(self) -> float:
        return self._spin

    @property
    def gyros_at_speed(self) -> bool:
        return self._spin >= SPIN_READY

    def set_mode(self, mode: int) -> None:
        """Switch the mode relays (the console's hold/set/release is the drivers' business)."""
        self._switch(dataclasses.replace(self.relays, mode=mode))

    def set_caging_inhibit(self, channel: str, inhibit: bool) -> None:
        flags = list(self.relays.caging_inhibit)
        flags[GYRO_CHANNELS.index(channel)] = bool(inhibit)
        x, y, z, xrd = flags
        self._switch(dataclasses.replace(self.relays, caging_inhibit=(x, y, z, xrd)))

    @property
    def clamped(self) -> bool:
        return self.relays.clamped

    def set_clamp(self, clamped: bool) -> None:
        """Clamp the platform to the table with the motor drive open, or release it (Ch. V B).

        The clamp catches the gimbals where they are: their rates go to zero at once and the
        angles hold; released, the loops take the platform from there. The interlocks are the
        relay node's business (``simhw.canopen_nodes.CanopenRelayNode``), not the physics'."""
        clamped = bool(clamped)
        if clamped == self.relays.clamped:
            return
        if clamped:
            plant = self._compiled.disc.plant
            for a in AXES:
                if f"omega_{a}" in plant.states:
                    self.x[plant.states.index(f"omega_{a}")] = 0.0
        self._switch(dataclasses.replace(self.relays, clamped=clamped))

    def set_torquer_bias_V(self, channel: str, volts: float) -> None:
        self._require(channel in GYRO_CHANNELS, f"unknown gyro channel {channel!r}")
        self.bias[channel] = float(volts)

    def set_command_torque_V(self, axis: str, volts: float) -> None:
        self._require(axis in AXES, f"unknown axis {axis!r}")
        self.vtd[axis] = float(volts)

    def set_ac_bias_V(self, axis: str, volts: float) -> None:
        self._require(axis in AXES, f"unknown axis {axis!r}")
        self.gamma_c[axis] = float(volts)

    def set_table(self, tilt_deg: float | None = None, spindle_deg: float | None = None) -> None:
        if tilt_deg is not None:
            self._require(0.0 <= tilt_deg <= 90.0, f"table tilt {tilt_deg} deg outside 0..90 deg")
            self.cfg.table.tilt_deg = float(tilt_deg)
        if spindle_deg is not None:
            self.cfg.table.spindle_deg = float(spindle_deg)

    def set_range(self, channel: str, range_V: float) -> None:
        self.chain.set_range(channel, range_V)

    @staticmethod
    def _require(ok: bool, msg: str) -> None:
        if not ok:
            raise ValueError(msg)

    # ------------------------------------------------------------------ model bookkeeping
    def _compile(self, relays: RelayState) -> CompiledPlant:
        cp = self._cache.get(relays)
        if cp is None:
            disc = discretize(build_plant(self.cfg, relays), self.dt)
            cp = CompiledPlant.build(disc if self._keep is None else reduce(disc, self._keep))
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[relays] = cp
        return cp

    def _switch(self, relays: RelayState) -> None:
        if relays != self.relays:
            self.relays = relays
            self._compiled = self._compile(relays)  # same state layout in every relay state

    def _slow_inputs(self, plant: Plant | None = None) -> np.ndarray:
        """The values of ``plant``'s slow inputs (default: the compiled plant's), in its order.

        Asked for at every set-point of a stream (250 a second), so the part a set-point cannot
        change (the earth rate and the g-drifts on the table's geometry) is kept per plant and
        geometry (``_slow_layout``), and only the set-points are filled in: the same values."""
        plant = plant or self._compiled.disc.plant
        cfg = self.cfg
        key = (
            cfg.table.tilt_deg,
            cfg.table.spindle_deg,
            cfg.table.base_azimuth_offset_deg,
            cfg.site.latitude_deg,
            cfg.site.earth_rate_rad_per_s,
        )
        lay = self._slow_layout
        if lay is None or lay[0] is not plant or lay[1] != key:
            lay = self._slow_layout = (plant, key, *self._slow_parts(plant, key))
        out = lay[2].copy()
        setpoints = [*self.vtd.values(), *self.gamma_c.values(), *self.bias.values()]
        for i, j in lay[3]:
            out[i] = setpoints[j]
        return out

    def _slow_parts(
        self, plant: Plant, key: tuple[float, float, float, float, float]
    ) -> tuple[np.ndarray, list[tuple[int, int]]]:
        """``plant``'s slow inputs on the geometry ``key`` with every set-point 0, and where each
        set-point goes: (slow input, its place in ``vtd``, ``gamma_c``, ``bias`` in turn)."""
        cfg = self.cfg
        w, f = self._table_geometry(key)
        axis_i = {"X": 0, "Y": 1, "Z": 2, "XRD": 0}
        setpoints = [f"vtd_{a}" for a in self.vtd] + [f"gc_{a}" for a in self.gamma_c]
        setpoints += [f"vb_{c}" for c in self.bias]
        values = {}
        for c in GYRO_CHANNELS:
            g = cfg.gyro[c]
            drift = (
                g.fixed_drift_urad_per_s
                + g.g_drift_x_urad_per_s_per_g * f[0]
                + g.g_drift_y_urad_per_s_per_g * f[1]
                + g.g_drift_z_urad_per_s_per_g * f[2]
            ) * URAD
            values[f"wconst_{c}"] = w[axis_i[c]] + drift
        names = plant.slow_inputs
        base = np.array([values.get(s, 0.0) for s in names])
        return base, [(i, setpoints.index(s)) for i, s in enumerate(names) if s in setpoints]

    def _table_geometry(
        self, key: tuple[float, float, float, float, float]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Earth rate and specific force on the platform axes for (tilt, spindle, azimuth offset
        deg, latitude deg, earth rate): asked for every block, changed by a table move."""
        if self._geometry is None or self._geometry[0] != key:
            tilt, spindle, offset, lat, rate = key
            axes = geometry.platform_axes_enu(
                math.radians(tilt), math.radians(spindle), math.radians(offset)
            )
            self._geometry = (
                key,
                geometry.earth_rate_platform(math.radians(lat), rate, axes),
                geometry.specific_force_platform(axes),
            )
        return self._geometry[1], self._geometry[2]

    def _settle(self) -> None:
        """Start in the steady state of the linear model for the present slow inputs.

        A spans 1e-6 (gyro) to 1e7 (filters): a least-squares solve with a relative cutoff
        would drop the gyro rows, so solve by LU, which pivots through the scaling. A reduced run
        solves the whole rig and keeps its part: a smaller LU would round differently, and the
        reduced run would no longer be the full run's to the bit.
        """
        plant = (
            self._compiled.disc.plant if self._keep is None else build_plant(self.cfg, self.relays)
        )
        slow = self._slow_inputs(plant)
        rhs = -plant.B[:, [plant.inputs.index(s) for s in plant.slow_inputs]] @ slow
        # The slow noise (offset jumps, 1/f, disturbance) already has a value at t = 0: the
        # platform has been following it, so it is part of the steady state too.
        for name in self.sources.names:
            if name in plant.inputs:
                rhs -= plant.B[:, plant.inputs.index(name)] * self.sources.initial(name)
        try:
            # LU's condition estimate sees the 1e-6..1e7 scaling as ill-conditioning (rcond ~1e-17
            # in Mode 5); the pivoted solve is right through it, and a result that is not is
            # caught below by its finiteness
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)
                x = scipy.linalg.solve(plant.A, rhs)
        except (scipy.linalg.LinAlgError, ValueError):
            log.warning("mode %d has no unique steady state; starting from rest", self.mode)
            return
        if np.all(np.isfinite(x)):
            kept_states = self._compiled.disc.plant.states
            self.x = x if self._keep is None else x[[plant.states.index(s) for s in kept_states]]

    def _spin_target(self) -> float:
        return 0.0 if self.relays.mode == 1 else 1.0

    # ------------------------------------------------------------------ stepping
    def advance(
        self,
        n: int,
        events: Sequence[tuple[int, Callable[[Simulator], object]]] = (),
        *,
        setpoints: bool = False,
    ) -> Block:
        """Simulate the next ``n`` output samples and return them as the ADC delivers them.

        ``events``: (k, fn) in order of k, 0 <= k < n: ``fn(self)`` runs before output sample
        k of the block, as between ``advance(k)`` and the rest: a set-point that steps inside
        the block (``simhw.rig_server``: a stream of set-points simulated in one block rather
        than one block each). The samples are those of the split run to the bit; only the
        physics steps between events, the noise, pickup and ADC chain run once for the block.
        ``fn`` may change the physics (set-points, relays, the table), not the ADC chain.
        ``setpoints``: every ``fn`` only sets inputs (V_Td, gamma_c, torquer biases) and reads
        nothing of the state, so the pieces between events run as one kernel call (the same
        arithmetic; a fn that switched the plant, or touched the state, would not be)."""
        if n < 0:
            raise ValueError(f"sample count {n} must be >= 0")
        ks = [k for k, _ in events]
        if any(not 0 <= k < n for k in ks) or ks != sorted(ks):
            raise ValueError(f"event samples {ks} must be ordered within 0..{n - 1}")
        t0 = self.time_s  # blocks always start on an output sample
        n_int = n * self.oversample
        chunks = []
        done = 0
        i = 0
        # the noise inputs drawn for the rest of the block at once, the pieces between events
        # served from it: (plant, its inputs, the step they start at)
        noise: tuple[CompiledPlant, np.ndarray, int] | None = None
        pieces: list[tuple[int, np.ndarray]] = []  # (steps, slow inputs) not yet run, from `at`
        at = 0

        def run_pending() -> None:
            if pieces:
                assert noise is not None
                cp, u, start = noise
                steps = sum(m for m, _ in pieces)
                chunks.append(self._run_pieces(cp, u[at - start : at - start + steps], pieces))
                pieces.clear()

        while done < n_int:
            while i < len(events) and events[i][0] * self.oversample <= done:
                events[i][1](self)
                i += 1
            m = n_int - done
            if i < len(events):
                m = min(m, events[i][0] * self.oversample - done)
            transient = self._spin_transient()
            if transient:
                m = min(m, max(1, int(0.25 / self.dt)))
            if noise is None or noise[0] is not self._compiled:
                run_pending()  # on the plant they were for
                if noise is not None:  # another plant from here on: its draws go back
                    self._unread(noise[0], noise[1][done - noise[2] :])
                noise = (self._compiled, self._noise(self._compiled, n_int - done), done)
            if not pieces:
                at = done
            pieces.append((m, self._slow_inputs()))
            if not setpoints or transient:
                run_pending()
            done += m
            self._evolve_spin(m * self.dt)
        run_pending()
        ny = len(self.channels)
        y = np.concatenate(chunks) if chunks else np.zeros((0, len(self._outputs)))
        analog = y[:, :ny]
        self._check_finite(analog, t0)
        for col, line in self._pickup:
            analog[:, col] += line.take(n_int)
        keep, volts, over = self.chain.process(analog)
        truth = {}
        if self.truth:
            for i, name in enumerate(TRUTH_CHANNELS):
                truth[name] = y[keep, ny + i]
        self.clock.advance_to(self.time_s)
        return Block(t0, self.rate_hz, self.channels, volts, over, truth)

    def _check_finite(self, analog: np.ndarray, t0: float) -> None:
        """Raise ``SimulationDiverged`` where an output is not finite or beyond ``DIVERGED_V``:
        the quantizer would otherwise write NaN as 0 V and the run would look quiet."""
        bad = ~np.isfinite(analog) | (np.abs(analog) > DIVERGED_V)
        if bad.any():
            i, j = (int(k[0]) for k in np.nonzero(bad))
            raise SimulationDiverged(
                f"the simulation diverged at t = {t0 + i * self.dt:.6g} s: {self.channels[j]} = {analog[i, j]:.3g} V "
                f"(beyond {DIVERGED_V:g} V or not a number); the configuration makes the plant unstable or "
                f"the step too coarse for it - check the values changed from the defaults"
            )

    def _spin_transient(self) -> bool:
        return abs(self._spin - self._spin_target()) > 1e-6

    def _evolve_spin(self, elapsed: float) -> None:
        """First-order wheel run-up/run-down reaching 99 % in the configured time."""
        target = self._spin_target()
        if not self._spin_transient():
            return
        p = self.cfg.gyros
        tau = (p.spin_up_time_s if target > self._spin else p.spin_down_time_s) / math.log(100.0)
        self._spin = target + (self._spin - target) * math.exp(-elapsed / tau)
        if abs(self._spin - target) < 1e-4:
            self._spin = target
        # The model is rebuilt for the speed rounded to SPIN_MODEL_STEP: each rebuild costs a
        # matrix exponential (~0.1 s), and nothing is measured while the wheels run up.
        spin = round(round(self._spin / SPIN_MODEL_STEP) * SPIN_MODEL_STEP, 6)
        self._switch(dataclasses.replace(self.relays, spin=spin))

    def _noise(self, cp: CompiledPlant, m: int) -> np.ndarray:
        """The next ``m`` internal steps of ``cp``'s noise inputs (its fast columns; the
        correlated parts' columns zero)."""
        fast, _ = self._layout(cp)
        u = np.zeros((m, len(cp.fast_cols)))
        for j, name in fast:
            u[:, j] = self.sources.take(name, m)
        return u

    def _unread(self, cp: CompiledPlant, u: np.ndarray) -> None:
        """Give back draws ``_noise`` made for ``cp`` and no step used: each input's stream
        continues from them, as if they had never been drawn."""
        for j, name in self._layout(cp)[0]:
            self.sources.unread(name, u[:, j])

    def _run_pieces(
        self, cp: CompiledPlant, u: np.ndarray, pieces: list[tuple[int, np.ndarray]]
    ) -> np.ndarray:
        """Plant ``cp`` over the noise inputs ``u`` (``_noise``), in ``pieces`` (steps, slow
        inputs) that follow one another: the outputs, in ``_outputs``'s order."""
        plant = cp.disc.plant
        _, order = self._layout(cp)
        y = np.empty((len(u), len(plant.outputs)))
        slows = cp.run_pieces(self.x, u, pieces, self.nl_state, y)
        names = tuple(plant.slow_inputs)
        # A set-point (V_Td, gamma_c, a torquer bias) steps at a piece's first sample: the analog
        # filter before the ADC sees a staircase there, whose sample at the edge is the mean of
        # its two sides, as the samples of smooth signals are their values; taking the new side
        # alone put every staircase half an internal step ahead of the smooth signals (V_Td's
        # direct path in pa against the compensation's, eq. 3.27)
        same = self._last_slow is not None and self._last_slow[0] == names
        before = self._last_slow[1] if same and self._last_slow is not None else slows[0]
        rows = np.cumsum([0] + [m for m, _ in pieces[:-1]])
        half_steps(cp.ds, slows, before, rows, y)
        self._last_slow = (names, pieces[-1][1])
        self.step += len(u)
        return y[:, order]

    def _layout(self, cp: CompiledPlant) -> tuple[list[tuple[int, str]], list[int]]:
        """(column, name) of ``cp``'s noise inputs and the output columns in ``_outputs``'s order
        (asked for every block; the last plant's kept)."""
        if self._last_layout is None or self._last_layout[0] is not cp:
            plant = cp.disc.plant
            fast = [
                (j, plant.inputs[i])
                for j, i in enumerate(cp.fast_cols)
                if not plant.inputs[i].startswith("corr_")
            ]
            self._last_layout = (cp, fast, [plant.outputs.index(c) for c in self._outputs])
        return self._last_layout[1], self._last_layout[2]

    def run(self, duration_s: float, block_s: float = 10.0):
        """Yield blocks covering ``duration_s`` seconds (rounded to whole samples)."""
        total = int(round(duration_s * self.rate_hz))
        per = max(1, int(round(block_s * self.rate_hz)))
        while total > 0:
            n = min(per, total)
            yield self.advance(n)
            total -= n

    def torquer_limit_V(self, channel: str) -> float:
        return torquer_limit_V(self.cfg, channel)
