"""Parameters of the simulated Fixed Base Simulator, with the thesis values as defaults.

Every value here is overridable from a TOML sim config (DESIGN.md section 7). Names carry
their units because this is an edge: a config file is written by people. The plant
(``simhw.plant``) converts to SI once, when it builds its state-space model.

Sources (Klinger 1974): platform Ch. III C-E and Table 5; bearings Ch. V F, eq. 5.2;
gyros Ch. II C.1.a and Tables 3-4; autocollimators Table 1 and eqs. 3.21-3.22.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivers.rig_datasheet import AXES, GYRO_CHANNELS

AC_AXES = ("X", "Y")
BEARING_MODELS = ("none", "viscous", "spring", "dahl")
#: The six legal modes of DESIGN.md section 4; 0 and 7 are disallowed by the console logic.
MODES = (1, 2, 3, 4, 5, 6)


class ConfigError(ValueError):
    """A sim config names an unknown key or gives a bad value; the message names both."""


def _f(
    default: float,
    *,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    doc: str = "",
) -> Any:
    """A float field with an allowed range checked by :func:`validate`."""
    return field(default=default, metadata={"lo": lo, "hi": hi, "lo_open": lo_open, "doc": doc})


@dataclass
class Site:
    latitude_deg: float = _f(37.43, lo=-90.0, hi=90.0, doc="Stanford")
    earth_rate_rad_per_s: float = _f(7.292115e-5, lo=0.0, lo_open=True)
    gravity_m_per_s2: float = _f(9.80665, lo=0.0, lo_open=True)


@dataclass
class Table:
    """Tilting rotary table (Ch. II C.4.b).

    ``tilt_deg`` turns the spindle from vertical toward north about the east-west shaft
    (0 = face horizontal; 90 - latitude = spindle polar, the thesis's "elevated to the local
    latitude"). ``spindle_deg`` turns the platform about the spindle (= platform Z).
    ``base_azimuth_offset_deg`` is the unknown azimuth error of the table base: at tilt 0
    the platform X axis points ``spindle_deg - base_azimuth_offset_deg`` from north
    towards west. Procedures must estimate it, never read it.
    """

    tilt_deg: float = _f(0.0, lo=0.0, hi=90.0)
    spindle_deg: float = _f(0.0, lo=-360.0, hi=360.0)
    base_azimuth_offset_deg: float = _f(0.12, lo=-10.0, hi=10.0)


@dataclass
class PlatformAxis:
    """One gimbal axis: inertia, gyro-gimbal viscous damping, motor and amplifier (Ch. III C-E)."""

    inertia_kg_m2: float = _f(0.70, lo=0.0, lo_open=True)
    gyro_damping_Nms: float = _f(1.02, lo=0.0)  # 2*Do on X, Do on Y and Z (eq. 3.31-3.33)
    extra_damping_Nms: float = _f(0.0, lo=0.0)  # effect `extra_damping`
    amp_gain: float = _f(302.0, lo=0.0, lo_open=True)  # Kp
    amp_limit_V: float = _f(28.0, lo=0.0, lo_open=True)  # 28 VDC supply
    command_divider: float = _f(0.0075, lo=0.0)  # Kd
    motor_torque_Nm_per_A: float = _f(0.53, lo=0.0, lo_open=True)  # Km
    back_emf_V_s: float = _f(0.53, lo=0.0)  # Kb
    armature_ohm: float = _f(23.0, lo=0.0, lo_open=True)  # Ra
    armature_H: float = _f(0.023, lo=0.0, lo_open=True)  # La
    stop_deg: float = _f(25.0, lo=0.0, lo_open=True)
    disturbance_torque_rms_Nm: float = _f(0.0, lo=0.0)  # effect `platform_disturbance`
    disturbance_corner_hz: float = _f(
        5.0, lo=0.0, lo_open=True
    )  # as the effect and docs/simhw.md 6


@dataclass
class Bearing:
    """Gimbal bearing torque model (Ch. V F). Dahl: dT/dtheta = eta (T -+ To)^2 (eq. 5.2)."""

    model: str = "dahl"
    To_Nm: float = _f(0.016, lo=0.0, lo_open=True)
    eta_per_Nm: float = _f(1.6e6, lo=0.0, lo_open=True)
    stiffness_Nm_per_rad: float = _f(410.0, lo=0.0)  # used by model "spring"
    damping_Nms: float = _f(0.05, lo=0.0)  # used by model "viscous"


@dataclass
class Compensation:
    """C(s) = (s/w2+1)(s/w3+1) / ((s/w1+1)(s/w4+1)(s/w5+1)(s/w6+1)), eq. 3.28 (rad/s)."""

    w1_rad_per_s: float = _f(0.15, lo=0.0, lo_open=True)
    w2_rad_per_s: float = _f(10.0, lo=0.0, lo_open=True)
    w3_rad_per_s: float = _f(30.0, lo=0.0, lo_open=True)
    w4_rad_per_s: float = _f(200.0, lo=0.0, lo_open=True)
    w5_rad_per_s: float = _f(1200.0, lo=0.0, lo_open=True)
    w6_rad_per_s: float = _f(5000.0, lo=0.0, lo_open=True)


@dataclass
class Autocollimator:
    """Primary autocollimator, one axis (Table 1, eqs. 3.21-3.22)."""

    control_scale_mV_per_urad: float = _f(5.70, lo=0.0, lo_open=True)
    control_filter_rad_per_s: float = _f(264.0, lo=0.0, lo_open=True)
    control_filter_zeta: float = _f(0.71, lo=0.0, lo_open=True)
    inst_scale_mV_per_urad: float = _f(5.63, lo=0.0, lo_open=True)
    inst_filter1_rad_per_s: float = _f(755.0, lo=0.0, lo_open=True)
    inst_filter2_rad_per_s: float = _f(1250.0, lo=0.0, lo_open=True)
    inst_filter2_zeta: float = _f(0.71, lo=0.0, lo_open=True)
    linear_range_urad: float = _f(2300.0, lo=0.0, lo_open=True)
    #: std of the control channel's noise-equivalent angle in 0.1-100 Hz (Table 1); the white
    #: level is derived from it together with the 1/f corner (docs/simhw.md).
    nea_urad: float = _f(0.451, lo=0.0)
    #: the 1/f noise: one-sided angle PSD W K(f), r = (fc/f)^slope, fc = ``flicker_corner_hz``,
    #: K = knee (1 + r) + (1 - knee) max(1, r) (``simhw.simulator.ac_knee``). Fig. 32 shows a
    #: white floor with 1/f below about 3 Hz; how the two meet (``flicker_knee``: 1 adds them,
    #: 0 is the sharp corner max(1, fc/f)) and the slope are unit-to-unit variation (DESIGN.md
    #: section 8: any knee between the two, slope -0.8 .. -1.2 in a nominal unit)
    flicker_corner_hz: float = _f(3.0, lo=0.0)
    flicker_knee: float = _f(1.0, lo=0.0, hi=1.0)
    flicker_slope: float = _f(1.0, lo=0.5, hi=2.0)
    #: the fraction of the white noise's PSD common to the X and Y channels (one source seen by
    #: both, Fig. 48: their coherence in the white band is the product of the two fractions)
    common_noise_fraction: float = _f(0.0, lo=0.0, hi=1.0)
    # Effects (DESIGN.md section 8); zero means absent.
    mount_freq_hz: float = _f(0.0, lo=0.0)
    mount_damping: float = _f(0.02, lo=0.0, lo_open=True)
    #: floor motion exciting the mount (angular acceleration, white): the undisturbed mount's
    #: peak PSD in the sensed angle, as a multiple of the autocollimator's white angle PSD W
    mount_excitation: float = _f(0.0, lo=0.0)
    delay_s: float = _f(0.0, lo=0.0, hi=0.05)
    #: an excess 1/f added to the unit's own, meeting the white level here (configs from before
    #: the ``flicker_noise`` effect set ``flicker_corner_hz`` instead; still honoured)
    extra_flicker_corner_hz: float = _f(0.0, lo=0.0)
    offset_jump_urad: float = _f(0.0, lo=0.0)
    offset_jump_interval_s: float = _f(100.0, lo=0.0, lo_open=True)


@dataclass
class Azimuth:
    """Azimuth autocollimator: dc electronics, pure 1/f noise, no filter (Table 1, Fig. 34)."""

    scale_mV_per_urad: float = _f(7.36, lo=0.0, lo_open=True)
    linear_range_urad: float = _f(5000.0, lo=0.0, lo_open=True)
    nea_urad: float = _f(2.78, lo=0.0)


#: The pickoff's discrete lines (Ch. V B.4: a 71 Hz pair 0.8 Hz apart, 102 Hz, 187 Hz) and the
#: share of the lines' variance each carries (sim parameters: the thesis gives no split).
PICKOFF_LINE_SHARES = ((70.6, 0.30), (71.4, 0.30), (102.0, 0.25), (187.0, 0.15))
#: "The discrete components contribute over 85 percent" of the pickoff noise (Ch. VI A).
PICKOFF_LINES_FRACTION = 0.85


def nominal_pickoff_lines(rms_urad: float) -> list[list[float]]:
    """The data sheet's pickoff lines for a channel of ``rms_urad`` rms noise in 0.1-200 Hz:
    together 85 % of its variance (Ch. VI A), split as ``PICKOFF_LINE_SHARES``. A sinusoid of
    amplitude a has variance a^2/2, so a line's amplitude is sqrt(2 share 0.85 rms^2); the
    white part is the rest (``simhw.simulator.pickoff_white_psd``)."""
    return [
        [f, math.sqrt(2.0 * share * PICKOFF_LINES_FRACTION * rms_urad**2)]
        for f, share in PICKOFF_LINE_SHARES
    ]


@dataclass
class GyroChannel:
    """One gyro channel (Ch. II C.1.a, Tables 3-4)."""

    torquer_scale_urad_per_s_per_V: float = _f(31.6, lo=0.0, lo_open=True)  # KTO
    pickoff_scale_mV_per_urad: float = _f(6.03, lo=0.0, lo_open=True)  # Kg
    pickoff_linear_range_urad: float = _f(1000.0, lo=0.0, lo_open=True)
    restraint_time_s: float = _f(424.0, lo=0.0, lo_open=True)  # h/k
    viscous_coupling_h_over_c: float = _f(1.96, lo=0.0, lo_open=True)  # h/c
    fixed_drift_urad_per_s: float = _f(0.35)
    g_drift_x_urad_per_s_per_g: float = _f(0.0)
    g_drift_y_urad_per_s_per_g: float = _f(0.0)
    g_drift_z_urad_per_s_per_g: float = _f(0.0)
    #: random drift (white rate noise, flicker bias instability, rate random walk)
    arw_urad_per_sqrt_s: float = _f(0.005, lo=0.0)
    bias_instability_urad_per_s: float = _f(0.02, lo=0.0)
    rrw_urad_per_s_per_sqrt_s: float = _f(2e-5, lo=0.0)
    #: pickoff noise rms in 0.1-200 Hz, lines included (Fig. 33: 6.2 X / 12.4 Y urad)
    pickoff_noise_rms_urad: float = _f(6.2, lo=0.0)
    #: discrete lines as (freq_hz, amplitude_urad) pairs (Ch. V B.4); by default they carry
    #: 85 % of the variance of the default ``pickoff_noise_rms_urad`` (:func:`nominal_pickoff_lines`);
    #: a config that lowers the rms below them must give its lines too
    pickoff_lines: list = field(default_factory=lambda: nominal_pickoff_lines(6.2))
    caging_natural_freq_rad_per_s: float = _f(0.1, lo=0.0, lo_open=True)
    caging_zeta: float = _f(0.7, lo=0.0, lo_open=True)
    #: the redundant channel keeps the Minuteman proportional-only caging amplifier (II C.1.a(7))
    caging_proportional_only: bool = False


@dataclass
class Gyros:
    """Properties common to both gyros and the torquer amplifiers (Ch. II C.1.a(1))."""

    angular_momentum_kg_m2_per_s: float = _f(1.0, lo=0.0, lo_open=True)
    torquer_caging_mA_per_V: float = _f(-6.04)  # KTC
    torquer_bias_mA_per_V: float = _f(-10.00)  # KTB
    sense_resistor_ohm: float = _f(92.1, lo=0.0, lo_open=True)
    max_rate_earth_rates: float = _f(3.5, lo=0.0, lo_open=True)
    spin_up_time_s: float = _f(120.0, lo=0.0, lo_open=True)  # to 99 % speed
    spin_down_time_s: float = _f(600.0, lo=0.0, lo_open=True)


@dataclass
class Sampling:
    """Recording chain (App. A.5, A.7): 3-pole anti-alias low-pass at 0.3 fs, then the ADC."""

    anti_alias_fraction: float = _f(0.3, lo=0.0, hi=0.5, lo_open=True)
    anti_alias_poles: int = 3
    adc_bits: int = 16
    default_range_V: float = _f(10.0, lo=0.0, lo_open=True)
    #: the plant runs at oversample x the output rate, and at least min_internal_rate_hz
    oversample: int = 2
    min_internal_rate_hz: float = _f(2000.0, lo=0.0, lo_open=True)


def _axis_defaults() -> dict[str, PlatformAxis]:
    # Kp from Ch. II C.4.a; inertias Ch. III C; D = 2 Do (X, both gyros), Do (Y, Z) (eq. 3.31).
    return {
        "X": PlatformAxis(inertia_kg_m2=0.70, gyro_damping_Nms=1.02, amp_gain=302.0, stop_deg=25.0),
        "Y": PlatformAxis(inertia_kg_m2=0.25, gyro_damping_Nms=0.51, amp_gain=164.0, stop_deg=90.0),
        "Z": PlatformAxis(
            inertia_kg_m2=0.52, gyro_damping_Nms=0.51, amp_gain=333.0, stop_deg=110.0
        ),
    }


def _bearing_defaults() -> dict[str, Bearing]:
    # eta To^2 = 410 (X) / 380 (Y) N m/rad; Z unmeasured in the thesis: X's values.
    return {
        "X": Bearing(eta_per_Nm=1.6e6, stiffness_Nm_per_rad=410.0),
        "Y": Bearing(eta_per_Nm=1.48e6, stiffness_Nm_per_rad=380.0),
        "Z": Bearing(eta_per_Nm=1.6e6, stiffness_Nm_per_rad=410.0),
    }


def _ac_defaults() -> dict[str, Autocollimator]:
    return {
        "X": Autocollimator(
            control_scale_mV_per_urad=5.70, inst_scale_mV_per_urad=5.63, nea_urad=0.451
        ),
        "Y": Autocollimator(
            control_scale_mV_per_urad=5.99, inst_scale_mV_per_urad=5.92, nea_urad=0.506
        ),
    }


def _gyro_defaults() -> dict[str, GyroChannel]:
    # KTO, Kg, h/k, h/c per channel (II C.1.a); drift values are sim parameters of our choosing.
    # Pickoff noise 6.2 (X) / 12.4 (Y) urad rms, Z and XRD as X (Fig. 33), 85 % of its variance
    # in the lines (Ch. VI A), so Y's lines are twice X's.
    return {
        "X": GyroChannel(
            31.6,
            6.03,
            restraint_time_s=424.0,
            viscous_coupling_h_over_c=1.96,
            fixed_drift_urad_per_s=0.35,
            g_drift_y_urad_per_s_per_g=0.08,
            pickoff_noise_rms_urad=6.2,
            pickoff_lines=nominal_pickoff_lines(6.2),
        ),
        "Y": GyroChannel(
            33.4,
            6.70,
            restraint_time_s=708.0,
            viscous_coupling_h_over_c=21.0,
            fixed_drift_urad_per_s=-0.22,
            g_drift_x_urad_per_s_per_g=-0.05,
            pickoff_noise_rms_urad=12.4,
            pickoff_lines=nominal_pickoff_lines(12.4),
        ),
        "Z": GyroChannel(
            34.1,
            7.51,
            restraint_time_s=1072.0,
            viscous_coupling_h_over_c=35.7,
            fixed_drift_urad_per_s=0.15,
            g_drift_x_urad_per_s_per_g=0.06,
            pickoff_noise_rms_urad=6.2,
            pickoff_lines=nominal_pickoff_lines(6.2),
        ),
        "XRD": GyroChannel(
            32.0,
            5.74,
            restraint_time_s=515.0,
            viscous_coupling_h_over_c=2.43,
            fixed_drift_urad_per_s=0.41,
            g_drift_z_urad_per_s_per_g=0.04,
            pickoff_noise_rms_urad=6.2,
            pickoff_lines=nominal_pickoff_lines(6.2),
            caging_natural_freq_rad_per_s=1.0,
            caging_proportional_only=True,
        ),
    }


@dataclass
class PickupLine:
    """Electrical pickup: a sinusoid added to a recorded channel (effect `pickup_line`)."""

    channel: str
    freq_hz: float
    amplitude_V: float


@dataclass
class SimConfig:
    """The whole simulated rig. ``SimConfig()`` is the thesis rig."""

    site: Site = field(default_factory=Site)
    table: Table = field(default_factory=Table)
    platform: dict[str, PlatformAxis] = field(default_factory=_axis_defaults)
    bearing: dict[str, Bearing] = field(default_factory=_bearing_defaults)
    compensation: Compensation = field(default_factory=Compensation)
    autocollimator: dict[str, Autocollimator] = field(default_factory=_ac_defaults)
    azimuth: Azimuth = field(default_factory=Azimuth)
    gyro: dict[str, GyroChannel] = field(default_factory=_gyro_defaults)
    gyros: Gyros = field(default_factory=Gyros)
    sampling: Sampling = field(default_factory=Sampling)
    pickup: list[PickupLine] = field(default_factory=list)

    def copy(self) -> SimConfig:
        """An independent copy (structural: every section, list and table its own; the values
        themselves are immutable). Not revalidated: model fits copy a config per trial."""
        return _clone(self)

    def without_random_drift(self) -> SimConfig:
        """A copy with the gyros' random drift switched off (fixed and g drift stay)."""
        cfg = self.copy()
        for ch in cfg.gyro.values():
            ch.arw_urad_per_sqrt_s = ch.bias_instability_urad_per_s = (
                ch.rrw_urad_per_s_per_sqrt_s
            ) = 0.0
        return cfg


_IMMUTABLE = (float, int, str, bool, type(None))


def _clone(obj: Any) -> Any:
    if isinstance(obj, _IMMUTABLE):
        return obj
    if isinstance(obj, dict):
        return {k: _clone(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return type(obj)(_clone(v) for v in obj)
    # a section (dataclass): its scalars shared, its containers cloned; made as copy.copy makes
    # it (no __init__, so no validation), without copy's protocol lookups (a fit copies a
    # config per trial)
    if not dataclasses.is_dataclass(obj):
        return copy.deepcopy(obj)
    new = object.__new__(type(obj))
    vars(new).update(
        {k: v if isinstance(v, _IMMUTABLE) else _clone(v) for k, v in vars(obj).items()}
    )
    return new


_KEYED = {
    "platform": (PlatformAxis, AXES),
    "bearing": (Bearing, AXES),
    "autocollimator": (Autocollimator, AC_AXES),
    "gyro": (GyroChannel, GYRO_CHANNELS),
}


def to_dict(cfg: SimConfig) -> dict[str, Any]:
    """A plain, TOML/JSON-friendly dict of the whole config."""
    return dataclasses.asdict(cfg)


def _set_fields(obj: Any, values: dict[str, Any], where: str) -> None:
    known = {f.name: f for f in dataclasses.fields(obj)}
    for key, value in values.items():
        name = f"{where}.{key}"
        if key not in known:
            raise ConfigError(
                f"sim config: unknown key '{name}' (known keys in [{where}]: "
                f"{', '.join(sorted(known))})"
            )
        current = getattr(obj, key)
        if isinstance(current, bool):
            if not isinstance(value, bool):
                raise ConfigError(f"sim config: {name} = {value!r} must be true or false")
        elif isinstance(current, int):
            if isinstance(value, float) and math.isfinite(value) and value.is_integer():
                value = int(value)
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigError(f"sim config: {name} = {value!r} must be a whole number")
        elif isinstance(current, float):
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ConfigError(f"sim config: {name} = {value!r} must be a number")
            value = float(value)
        elif isinstance(current, list) and not isinstance(value, list):
            raise ConfigError(f"sim config: {name} = {value!r} must be a list")
        elif isinstance(current, str) and not isinstance(value, str):
            raise ConfigError(f"sim config: {name} = {value!r} must be a string")
        setattr(obj, key, value)


def from_dict(data: dict[str, Any], base: SimConfig | None = None) -> SimConfig:
    """Overlay ``data`` (as parsed from TOML) on ``base`` (default: the thesis rig), validated."""
    cfg = SimConfig() if base is None else from_dict(to_dict(base))
    for section, value in data.items():
        if section == "pickup":
            if not isinstance(value, list):
                raise ConfigError("sim config: [[pickup]] must be an array of tables")
            cfg.pickup = []
            for i, item in enumerate(value):
                if not isinstance(item, dict):
                    raise ConfigError(
                        f"sim config: pickup[{i}] = {item!r} must be a table "
                        "(channel, freq_hz, amplitude_V)"
                    )
                line = PickupLine(channel="", freq_hz=0.0, amplitude_V=0.0)
                _set_fields(line, item, f"pickup[{i}]")
                cfg.pickup.append(line)
        elif section in _KEYED:
            _, keys = _KEYED[section]
            if not isinstance(value, dict):
                raise ConfigError(f"sim config: [{section}] must be a table of {', '.join(keys)}")
            for key, sub in value.items():
                if key not in keys:
                    raise ConfigError(
                        f"sim config: unknown key '{section}.{key}' (known: {', '.join(keys)})"
                    )
                if not isinstance(sub, dict):
                    raise ConfigError(f"sim config: [{section}.{key}] must be a table")
                _set_fields(getattr(cfg, section)[key], sub, f"{section}.{key}")
        elif section in {f.name for f in dataclasses.fields(SimConfig)}:
            if not isinstance(value, dict):
                raise ConfigError(f"sim config: [{section}] must be a table")
            _set_fields(getattr(cfg, section), value, section)
        else:
            known = sorted(f.name for f in dataclasses.fields(SimConfig))
            raise ConfigError(
                f"sim config: unknown key '{section}' (known sections: {', '.join(known)})"
            )
    validate(cfg)
    return cfg


def config_stamp(path: str | Path | None) -> dict[str, str] | None:
    """A sim config as every result names it (``daq.provenance``): its path and the SHA-256 of
    its content (the path alone does not say which model ran: the file may change between
    runs). None: the built-in thesis rig."""
    if path is None:
        return None
    digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    return {"path": str(Path(path).resolve()), "sha256": digest}


def load_config(path: str | Path | None) -> SimConfig:
    """Read a TOML sim config; ``None`` gives the thesis rig."""
    if path is None:
        return SimConfig()
    if not str(path).strip():
        raise ConfigError(f"sim config: {str(path)!r} is an empty path; give a .toml file")
    path = Path(path)
    if path.exists() and not path.is_file():
        # a FIFO or a device would block the read (or never end): refused, as the run-file reader does
        raise ConfigError(
            f"sim config: {path} is not a regular file (a folder, FIFO or device); give a .toml file"
        )
    try:
        with path.open("rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"sim config: file not found: {path}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"sim config: {path} is not valid TOML: {exc}") from None
    except OSError as exc:
        raise ConfigError(f"sim config: cannot read {path}: {exc.strerror or exc}") from None
    return from_dict(data)


def _check_range(obj: Any, where: str) -> None:
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        lo, hi, lo_open = f.metadata.get("lo"), f.metadata.get("hi"), f.metadata.get("lo_open")
        if isinstance(value, float):
            name = f"{where}.{f.name}"
            if not math.isfinite(value):
                raise ConfigError(f"sim config: {name} = {value} must be finite")
            if lo is not None and (value < lo or (lo_open and value == lo)):
                rel = ">" if lo_open else ">="
                raise ConfigError(
                    f"sim config: {name} = {value} is out of range (must be {rel} {lo})"
                )
            if hi is not None and value > hi:
                raise ConfigError(f"sim config: {name} = {value} is out of range (must be <= {hi})")


def validate(cfg: SimConfig) -> None:
    """Raise :class:`ConfigError` naming the first bad value."""
    _check_range(cfg.site, "site")
    _check_range(cfg.table, "table")
    _check_range(cfg.compensation, "compensation")
    _check_range(cfg.azimuth, "azimuth")
    _check_range(cfg.gyros, "gyros")
    _check_range(cfg.sampling, "sampling")
    for section, (_, keys) in _KEYED.items():
        for key in keys:
            _check_range(getattr(cfg, section)[key], f"{section}.{key}")
    for axis, b in cfg.bearing.items():
        if b.model not in BEARING_MODELS:
            raise ConfigError(
                f"sim config: bearing.{axis}.model = {b.model!r} is not one of "
                f"{', '.join(BEARING_MODELS)}"
            )
    for name, ch in cfg.gyro.items():
        for i, line in enumerate(ch.pickoff_lines):
            if (
                not isinstance(line, (list, tuple))
                or len(line) != 2
                or not all(
                    isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                    for v in line
                )
                or line[0] <= 0
                or line[1] < 0
            ):
                raise ConfigError(
                    f"sim config: gyro.{name}.pickoff_lines[{i}] = {line!r} must be "
                    "[freq_hz > 0, amplitude_urad >= 0]"
                )
        lines_var = sum(a * a / 2 for _, a in ch.pickoff_lines)
        if lines_var > ch.pickoff_noise_rms_urad**2:
            raise ConfigError(
                f"sim config: gyro.{name}.pickoff_lines carry {math.sqrt(lines_var):.3g} urad rms, "
                f"more than pickoff_noise_rms_urad = {ch.pickoff_noise_rms_urad}"
            )
    s = cfg.sampling
    if s.adc_bits < 8 or s.adc_bits > 24:
        raise ConfigError(f"sim config: sampling.adc_bits = {s.adc_bits} is out of range (8..24)")
    if s.anti_alias_poles < 1 or s.anti_alias_poles > 8:
        raise ConfigError(
            f"sim config: sampling.anti_alias_poles = {s.anti_alias_poles} is out of range (1..8)"
        )
    if s.oversample < 1 or s.oversample > 64:
        raise ConfigError(
            f"sim config: sampling.oversample = {s.oversample} is out of range (1..64)"
        )
    for i, p in enumerate(cfg.pickup):
        _check_range(p, f"pickup[{i}]")
        if p.freq_hz <= 0:
            raise ConfigError(f"sim config: pickup[{i}].freq_hz = {p.freq_hz} must be > 0")
        if p.amplitude_V < 0:
            raise ConfigError(f"sim config: pickup[{i}].amplitude_V = {p.amplitude_V} must be >= 0")
