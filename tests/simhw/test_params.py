"""Sim-config parameters: thesis defaults, validation of overrides, TOML loading, copies.

``SimConfig()`` is the thesis rig (Klinger 1974); every override comes from a TOML file
written by people, so every bad key or value must end in a :class:`ConfigError` whose
message names the dotted key (and the value and limit where there is one).
"""

from __future__ import annotations

import dataclasses
import math

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from simhw import config as P
from simhw.bearing import dahl_stiffness
from simhw.config import (
    AXES,
    GYRO_CHANNELS,
    ConfigError,
    SimConfig,
    from_dict,
    load_config,
    to_dict,
    validate,
)

FAST = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


# --------------------------------------------------------------------------- thesis defaults
def test_default_config_is_valid():
    validate(SimConfig())


def test_default_platform_inertias_and_amplifier_gains_are_the_thesis_values():
    cfg = SimConfig()
    assert {a: cfg.platform[a].inertia_kg_m2 for a in AXES} == {"X": 0.70, "Y": 0.25, "Z": 0.52}
    assert {a: cfg.platform[a].amp_gain for a in AXES} == {"X": 302.0, "Y": 164.0, "Z": 333.0}


def test_default_gyro_damping_is_two_Do_on_X_and_Do_on_Y_and_Z():
    cfg = SimConfig()
    do = cfg.platform["Y"].gyro_damping_Nms
    assert cfg.platform["Z"].gyro_damping_Nms == do
    assert cfg.platform["X"].gyro_damping_Nms == pytest.approx(2 * do)


def test_default_gyro_torquer_and_pickoff_scales_are_the_thesis_values():
    cfg = SimConfig()
    kto = {c: cfg.gyro[c].torquer_scale_urad_per_s_per_V for c in GYRO_CHANNELS}
    kg = {c: cfg.gyro[c].pickoff_scale_mV_per_urad for c in GYRO_CHANNELS}
    assert kto == {"X": 31.6, "Y": 33.4, "Z": 34.1, "XRD": 32.0}
    assert kg == {"X": 6.03, "Y": 6.70, "Z": 7.51, "XRD": 5.74}


def test_default_bearing_small_motion_stiffness_is_410_on_X_and_379_on_Y():
    cfg = SimConfig()
    kx = dahl_stiffness(cfg.bearing["X"].To_Nm, cfg.bearing["X"].eta_per_Nm)
    ky = dahl_stiffness(cfg.bearing["Y"].To_Nm, cfg.bearing["Y"].eta_per_Nm)
    assert kx == pytest.approx(410.0, rel=0.01)
    assert ky == pytest.approx(379.0, rel=0.01)
    assert all(cfg.bearing[a].model == "dahl" for a in AXES)


def test_default_spring_stiffness_agrees_with_dahl_small_motion_stiffness():
    cfg = SimConfig()
    for a in AXES:
        b = cfg.bearing[a]
        assert b.stiffness_Nm_per_rad == pytest.approx(
            dahl_stiffness(b.To_Nm, b.eta_per_Nm), rel=0.01
        )


def test_default_redundant_channel_keeps_proportional_only_caging():
    cfg = SimConfig()
    assert cfg.gyro["XRD"].caging_proportional_only is True
    assert not any(cfg.gyro[c].caging_proportional_only for c in ("X", "Y", "Z"))


def test_default_pickoff_lines_fit_inside_the_pickoff_noise_rms():
    for c, ch in SimConfig().gyro.items():
        lines_rms = math.sqrt(sum(a * a / 2 for _, a in ch.pickoff_lines))
        assert 0 < lines_rms <= ch.pickoff_noise_rms_urad, c


@pytest.mark.parametrize("channel, rms", [("X", 6.2), ("Y", 12.4), ("Z", 6.2), ("XRD", 6.2)])
def test_default_pickoff_lines_carry_85_percent_of_the_variance_split_30_30_25_15(channel, rms):
    # Ch. VI A: "the discrete components contribute over 85 percent"; a line of amplitude a
    # has variance a^2/2
    ch = SimConfig().gyro[channel]
    assert ch.pickoff_noise_rms_urad == rms
    assert [f for f, _ in ch.pickoff_lines] == [70.6, 71.4, 102.0, 187.0]
    shares = [a * a / 2 / (0.85 * rms**2) for _, a in ch.pickoff_lines]
    assert shares == pytest.approx([0.30, 0.30, 0.25, 0.15], rel=1e-12)


def test_y_pickoff_lines_are_twice_x_s():
    cfg = SimConfig()
    assert [a for _, a in cfg.gyro["Y"].pickoff_lines] == pytest.approx(
        [2 * a for _, a in cfg.gyro["X"].pickoff_lines], rel=1e-12
    )
    assert P.GyroChannel().pickoff_lines == cfg.gyro["X"].pickoff_lines  # a bare channel is X's


def test_a_config_lowering_the_pickoff_rms_below_the_default_lines_must_give_its_lines():
    with pytest.raises(ConfigError, match="gyro.Y.pickoff_lines carry 11.4 urad rms"):
        from_dict({"gyro": {"Y": {"pickoff_noise_rms_urad": 9.0}}})
    cfg = from_dict(
        {
            "gyro": {
                "Y": {"pickoff_noise_rms_urad": 9.0, "pickoff_lines": P.nominal_pickoff_lines(9.0)}
            }
        }
    )
    assert cfg.gyro["Y"].pickoff_lines == P.nominal_pickoff_lines(9.0)


def test_default_pickoff_white_part_is_the_other_15_percent():
    from simhw.simulator import PICKOFF_BAND_HZ, pickoff_white_psd

    for ch in SimConfig().gyro.values():
        white_var = pickoff_white_psd(ch.pickoff_noise_rms_urad, ch.pickoff_lines) * (
            PICKOFF_BAND_HZ[1] - PICKOFF_BAND_HZ[0]
        )
        assert white_var == pytest.approx(0.15 * (ch.pickoff_noise_rms_urad * 1e-6) ** 2, rel=1e-9)


def test_autocollimator_knee_and_mount_excitation_default_to_the_plain_unit():
    for ac in SimConfig().autocollimator.values():
        assert (ac.flicker_knee, ac.flicker_slope, ac.mount_excitation) == (1.0, 1.0, 0.0)


def test_autocollimator_knee_slope_and_mount_excitation_are_read_from_a_config():
    cfg = from_dict(
        {
            "autocollimator": {
                "Y": {"flicker_knee": 0.0, "flicker_slope": 1.2, "mount_excitation": 30}
            }
        }
    )
    ac = cfg.autocollimator["Y"]
    assert (ac.flicker_knee, ac.flicker_slope, ac.mount_excitation) == (0.0, 1.2, 30.0)
    assert cfg.autocollimator["X"].flicker_knee == 1.0


def test_old_extra_flicker_corner_key_still_loads():
    cfg = from_dict({"autocollimator": {"X": {"extra_flicker_corner_hz": 8.0}}})
    assert cfg.autocollimator["X"].extra_flicker_corner_hz == 8.0


def test_default_site_is_stanford_and_has_no_pickup():
    cfg = SimConfig()
    assert cfg.site.latitude_deg == pytest.approx(37.43)
    assert cfg.site.earth_rate_rad_per_s == pytest.approx(7.292115e-5)
    assert cfg.pickup == []


# --------------------------------------------------------------------------- from_dict: keys
def test_from_dict_empty_gives_the_thesis_rig():
    assert from_dict({}) == SimConfig()


def test_from_dict_overrides_only_the_named_fields():
    cfg = from_dict(
        {"gyro": {"Y": {"torquer_scale_urad_per_s_per_V": 30.0}}, "site": {"latitude_deg": -12.5}}
    )
    assert cfg.gyro["Y"].torquer_scale_urad_per_s_per_V == 30.0
    assert cfg.site.latitude_deg == -12.5
    expected = SimConfig()
    expected.gyro["Y"].torquer_scale_urad_per_s_per_V = 30.0
    expected.site.latitude_deg = -12.5
    assert cfg == expected


def test_from_dict_overlays_on_a_base_without_touching_it():
    base = from_dict({"table": {"tilt_deg": 52.57}})
    cfg = from_dict({"table": {"spindle_deg": 90.0}}, base=base)
    assert (cfg.table.tilt_deg, cfg.table.spindle_deg) == (52.57, 90.0)
    assert base.table.spindle_deg == 0.0


def test_from_dict_integer_value_for_float_field_becomes_float():
    cfg = from_dict({"platform": {"X": {"inertia_kg_m2": 1}}})
    assert cfg.platform["X"].inertia_kg_m2 == 1.0
    assert isinstance(cfg.platform["X"].inertia_kg_m2, float)


def test_from_dict_builds_pickup_lines():
    cfg = from_dict({"pickup": [{"channel": "ac_x_ctl", "freq_hz": 200.0, "amplitude_V": 0.003}]})
    assert cfg.pickup == [P.PickupLine("ac_x_ctl", 200.0, 0.003)]


@pytest.mark.parametrize(
    "data, key",
    [
        ({"nosuch": {}}, "'nosuch'"),
        ({"gyro": {"W": {}}}, "'gyro.W'"),
        ({"gyro": {"X": {"foo": 1.0}}}, "'gyro.X.foo'"),
        ({"platform": {"XRD": {}}}, "'platform.XRD'"),
        ({"autocollimator": {"Z": {}}}, "'autocollimator.Z'"),
        ({"autocollimator": {"X": {"flicker_form": 0.5}}}, "'autocollimator.X.flicker_form'"),
        ({"site": {"latitude": 10.0}}, "'site.latitude'"),
        ({"pickup": [{"channel": "ac_x_ctl", "freq_hz": 1.0, "ampl": 1.0}]}, "'pickup[0].ampl'"),
    ],
)
def test_unknown_key_raises_config_error_naming_the_full_dotted_key(data, key):
    with pytest.raises(ConfigError, match="unknown key") as exc:
        from_dict(data)
    assert key in str(exc.value)


def test_unknown_field_message_lists_the_known_fields():
    with pytest.raises(ConfigError) as exc:
        from_dict({"site": {"lat": 1.0}})
    assert "latitude_deg" in str(exc.value)


@pytest.mark.parametrize(
    "data, fragments",
    [
        ({"platform": {"X": {"inertia_kg_m2": -0.1}}}, ["platform.X.inertia_kg_m2", "-0.1", "> 0"]),
        ({"platform": {"Y": {"inertia_kg_m2": 0.0}}}, ["platform.Y.inertia_kg_m2", "0.0", "> 0"]),
        ({"site": {"latitude_deg": 91.0}}, ["site.latitude_deg", "91.0", "<= 90"]),
        ({"table": {"tilt_deg": -1}}, ["table.tilt_deg", "-1", ">= 0"]),
        (
            {"autocollimator": {"X": {"delay_s": 0.1}}},
            ["autocollimator.X.delay_s", "0.1", "<= 0.05"],
        ),
        (
            {"autocollimator": {"X": {"flicker_knee": 1.5}}},
            ["autocollimator.X.flicker_knee", "1.5", "<= 1.0"],
        ),
        (
            {"autocollimator": {"Y": {"flicker_knee": -0.1}}},
            ["autocollimator.Y.flicker_knee", "-0.1", ">= 0.0"],
        ),
        (
            {"autocollimator": {"X": {"flicker_slope": 0.4}}},
            ["autocollimator.X.flicker_slope", "0.4", ">= 0.5"],
        ),
        (
            {"autocollimator": {"X": {"flicker_slope": 2.5}}},
            ["autocollimator.X.flicker_slope", "2.5", "<= 2.0"],
        ),
        (
            {"autocollimator": {"X": {"mount_excitation": -1.0}}},
            ["autocollimator.X.mount_excitation", "-1.0", ">= 0.0"],
        ),
        ({"bearing": {"Z": {"damping_Nms": -1.0}}}, ["bearing.Z.damping_Nms", "-1.0", ">= 0"]),
        ({"sampling": {"adc_bits": 30}}, ["sampling.adc_bits", "30", "8..24"]),
        ({"sampling": {"oversample": 0}}, ["sampling.oversample", "0", "1..64"]),
        ({"sampling": {"anti_alias_poles": 9}}, ["sampling.anti_alias_poles", "9", "1..8"]),
    ],
)
def test_out_of_range_value_raises_config_error_naming_key_value_and_limit(data, fragments):
    with pytest.raises(ConfigError) as exc:
        from_dict(data)
    for frag in fragments:
        assert frag in str(exc.value)


@pytest.mark.parametrize(
    "data, fragments",
    [
        (
            {"platform": {"X": {"inertia_kg_m2": "heavy"}}},
            ["platform.X.inertia_kg_m2", "'heavy'", "number"],
        ),
        (
            {"platform": {"X": {"inertia_kg_m2": True}}},
            ["platform.X.inertia_kg_m2", "True", "number"],
        ),
        ({"sampling": {"adc_bits": False}}, ["sampling.adc_bits", "False", "number"]),
        (
            {"gyro": {"XRD": {"caging_proportional_only": 1}}},
            ["gyro.XRD.caging_proportional_only", "1", "true or false"],
        ),
        ({"bearing": {"X": {"model": 3}}}, ["bearing.X.model", "3", "string"]),
        (
            {"bearing": {"X": {"model": "coulomb"}}},
            ["bearing.X.model", "'coulomb'", "none, viscous, spring, dahl"],
        ),
        ({"bearing": {"Y": {"model": "Dahl"}}}, ["bearing.Y.model", "'Dahl'"]),
        ({"site": {"latitude_deg": math.nan}}, ["site.latitude_deg", "nan", "finite"]),
        (
            {"gyro": {"Z": {"fixed_drift_urad_per_s": math.inf}}},
            ["gyro.Z.fixed_drift_urad_per_s", "inf", "finite"],
        ),
        (
            {"compensation": {"w1_rad_per_s": -math.inf}},
            ["compensation.w1_rad_per_s", "-inf", "finite"],
        ),
        (
            {"gyro": {"X": {"pickoff_lines": [[0.0, 1.0]]}}},
            ["gyro.X.pickoff_lines[0]", "freq_hz > 0"],
        ),
        ({"gyro": {"X": {"pickoff_lines": [[70.0, 1.0, 2.0]]}}}, ["gyro.X.pickoff_lines[0]"]),
        (
            {"gyro": {"X": {"pickoff_lines": [[70.0, 100.0]]}}},
            ["gyro.X.pickoff_lines", "pickoff_noise_rms_urad"],
        ),
        (
            {"pickup": [{"channel": "ac_x_ctl", "freq_hz": 0.0, "amplitude_V": 1.0}]},
            ["pickup[0].freq_hz", "> 0"],
        ),
        ({"pickup": {"channel": "ac_x_ctl"}}, ["[[pickup]]", "array"]),
        ({"site": 3.0}, ["[site]", "table"]),
        ({"gyro": [1, 2]}, ["[gyro]", "table"]),
        ({"gyro": {"X": 5}}, ["[gyro.X]", "table"]),
    ],
)
def test_bad_value_raises_config_error_naming_key_and_value(data, fragments):
    with pytest.raises(ConfigError) as exc:
        from_dict(data)
    for frag in fragments:
        assert frag in str(exc.value)


def test_config_error_is_a_value_error():
    assert issubclass(ConfigError, ValueError)


# --------------------------------------------------------------------------- known bugs
@pytest.mark.parametrize("value", [math.nan, math.inf])
def test_nonfinite_value_for_integer_field_raises_config_error(value):
    with pytest.raises(ConfigError, match="sampling.adc_bits"):
        from_dict({"sampling": {"adc_bits": value}})


def test_fractional_value_for_integer_field_is_rejected():
    with pytest.raises(ConfigError, match="sampling.adc_bits"):
        from_dict({"sampling": {"adc_bits": 12.7}})


@pytest.mark.parametrize("item", [1, "ac_x_ctl", [200.0, 0.003]])
def test_pickup_entry_that_is_not_a_table_raises_config_error(item):
    with pytest.raises(ConfigError, match=r"pickup\[0\]"):
        from_dict({"pickup": [item]})


def test_pickoff_lines_that_is_not_a_list_raises_config_error():
    with pytest.raises(ConfigError, match="gyro.X.pickoff_lines"):
        from_dict({"gyro": {"X": {"pickoff_lines": 5}}})


@pytest.mark.parametrize(
    "field, value", [("freq_hz", math.nan), ("freq_hz", math.inf), ("amplitude_V", math.inf)]
)
def test_nonfinite_pickup_value_raises_config_error(field, value):
    item = {"channel": "ac_x_ctl", "freq_hz": 200.0, "amplitude_V": 0.003} | {field: value}
    with pytest.raises(ConfigError, match=f"pickup.0..{field}"):
        from_dict({"pickup": [item]})


@pytest.mark.parametrize("line", [[70.6, math.nan], [math.inf, 1.0]])
def test_nonfinite_pickoff_line_raises_config_error(line):
    with pytest.raises(ConfigError, match="gyro.X.pickoff_lines"):
        from_dict({"gyro": {"X": {"pickoff_lines": [line]}}})


# --------------------------------------------------------------------------- from_dict: fuzz
_SECTIONS = [f.name for f in dataclasses.fields(SimConfig)]
_json_scalars = st.one_of(
    st.booleans(), st.integers(-(10**6), 10**6), st.floats(allow_nan=True), st.text(max_size=8)
)
_str_or_section = st.one_of(st.text(max_size=12), st.sampled_from(_SECTIONS))


@FAST
@given(
    st.dictionaries(
        _str_or_section,
        st.one_of(
            st.text(max_size=12),
            st.dictionaries(st.text(max_size=8), st.text(max_size=8), max_size=3),
        ),
        max_size=4,
    )
)
def test_from_dict_on_random_string_mappings_returns_config_or_raises_config_error(data):
    try:
        cfg = from_dict(data)
    except ConfigError:
        return
    assert isinstance(cfg, SimConfig)


def _fields(cls):
    return [f.name for f in dataclasses.fields(cls)]


_value = st.one_of(
    _json_scalars,
    st.lists(_json_scalars, max_size=3),
    st.lists(st.lists(st.one_of(st.floats(), st.integers(-5, 500)), max_size=3), max_size=3),
)


def _table(cls):
    return st.dictionaries(st.sampled_from(_fields(cls)), _value, max_size=3)


_plain = ["site", "table", "compensation", "azimuth", "gyros", "sampling"]
_toml_like_config = st.lists(
    st.one_of(
        st.sampled_from(_plain).flatmap(
            lambda s: st.tuples(st.just(s), _table(type(getattr(SimConfig(), s))))
        ),
        st.sampled_from(sorted(P._KEYED)).flatmap(
            lambda s: st.tuples(
                st.just(s),
                st.dictionaries(
                    st.sampled_from(P._KEYED[s][1]), _table(P._KEYED[s][0]), max_size=2
                ),
            )
        ),
        st.tuples(
            st.just("pickup"), st.lists(st.one_of(_json_scalars, _table(P.PickupLine)), max_size=2)
        ),
    ),
    max_size=3,
).map(dict)


@FAST
@given(_toml_like_config)
@example({"pickup": [1]})
@example({"gyro": {"X": {"pickoff_lines": 5}}})
@example({"sampling": {"adc_bits": math.nan}})
def test_from_dict_on_any_toml_like_value_returns_config_or_raises_config_error(data):
    try:
        cfg = from_dict(data)
    except ConfigError:
        return
    assert isinstance(cfg, SimConfig)


# --------------------------------------------------------------------------- load_config
def test_load_config_none_gives_the_thesis_rig():
    assert load_config(None) == SimConfig()


def test_load_config_reads_overrides_from_toml(tmp_path):
    path = tmp_path / "rig.toml"
    path.write_text(
        "[site]\nlatitude_deg = 45.5\n\n"
        "[gyro.X]\ntorquer_scale_urad_per_s_per_V = 30.25\n\n"
        '[bearing.Y]\nmodel = "spring"\nstiffness_Nm_per_rad = 500\n\n'
        '[[pickup]]\nchannel = "ac_y_ctl"\nfreq_hz = 60.0\namplitude_V = 0.01\n',
        encoding="utf-8",
    )
    cfg = load_config(path)
    assert cfg.site.latitude_deg == 45.5
    assert cfg.gyro["X"].torquer_scale_urad_per_s_per_V == 30.25
    assert cfg.bearing["Y"].model == "spring"
    assert cfg.bearing["Y"].stiffness_Nm_per_rad == 500.0
    assert cfg.pickup == [P.PickupLine("ac_y_ctl", 60.0, 0.01)]
    expected = SimConfig()
    expected.site.latitude_deg = 45.5
    expected.gyro["X"].torquer_scale_urad_per_s_per_V = 30.25
    expected.bearing["Y"].model = "spring"
    expected.bearing["Y"].stiffness_Nm_per_rad = 500.0
    expected.pickup = [P.PickupLine("ac_y_ctl", 60.0, 0.01)]
    assert cfg == expected


def test_load_config_accepts_a_str_path(tmp_path):
    path = tmp_path / "rig.toml"
    path.write_text("[table]\ntilt_deg = 52.57\n", encoding="utf-8")
    assert load_config(str(path)).table.tilt_deg == 52.57


def test_load_config_missing_file_raises_config_error_naming_the_path(tmp_path):
    path = tmp_path / "absent.toml"
    with pytest.raises(ConfigError, match="not found") as exc:
        load_config(path)
    assert str(path) in str(exc.value)


def test_load_config_invalid_toml_raises_config_error_naming_the_path(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[site\nlatitude_deg = = 3\n", encoding="utf-8")
    with pytest.raises(ConfigError, match="not valid TOML") as exc:
        load_config(path)
    assert str(path) in str(exc.value)


def test_load_config_bad_value_in_file_raises_config_error_naming_the_key(tmp_path):
    path = tmp_path / "rig.toml"
    path.write_text("[platform.Z]\ninertia_kg_m2 = -2.0\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"platform\.Z\.inertia_kg_m2"):
        load_config(path)


def test_load_config_non_utf8_file_raises_config_error(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes(b"[site]\n# Stanford \xe9t\xe9\nlatitude_deg = 37.0\n")
    with pytest.raises(ConfigError):
        load_config(path)


def test_load_config_directory_raises_config_error(tmp_path):
    with pytest.raises(ConfigError):
        load_config(tmp_path)


# --------------------------------------------------------------------------- copies
def test_to_dict_from_dict_round_trips_the_default_config():
    assert from_dict(to_dict(SimConfig())) == SimConfig()


def test_copy_is_equal_but_deep():
    orig = from_dict({"pickup": [{"channel": "ac_x_ctl", "freq_hz": 200.0, "amplitude_V": 0.003}]})
    cp = orig.copy()
    assert cp == orig
    cp.platform["X"].inertia_kg_m2 = 9.0
    cp.bearing["Y"].model = "none"
    cp.gyro["Z"].pickoff_lines[0][1] = 0.0
    cp.gyro["X"].pickoff_lines.append([10.0, 1.0])
    cp.pickup[0].amplitude_V = 1.0
    cp.pickup.append(P.PickupLine("ac_y_ctl", 1.0, 1.0))
    cp.site.latitude_deg = 0.0
    assert orig == from_dict(
        {"pickup": [{"channel": "ac_x_ctl", "freq_hz": 200.0, "amplitude_V": 0.003}]}
    )
    assert orig.platform["X"].inertia_kg_m2 == 0.70
    assert orig.gyro["Z"].pickoff_lines[0][1] == SimConfig().gyro["Z"].pickoff_lines[0][1]


def test_without_random_drift_zeroes_only_the_random_drift_terms():
    cfg = SimConfig()
    quiet = cfg.without_random_drift()
    random_fields = {
        "arw_urad_per_sqrt_s",
        "bias_instability_urad_per_s",
        "rrw_urad_per_s_per_sqrt_s",
    }
    for c in GYRO_CHANNELS:
        for f in random_fields:
            assert getattr(quiet.gyro[c], f) == 0.0
            assert getattr(cfg.gyro[c], f) > 0.0  # the original keeps them
    # Everything else is unchanged, fixed and g drift included.
    a, b = to_dict(cfg), to_dict(quiet)
    for c in GYRO_CHANNELS:
        for f in random_fields:
            del a["gyro"][c][f], b["gyro"][c][f]
    assert a == b
    assert quiet.gyro["X"].fixed_drift_urad_per_s == 0.35
