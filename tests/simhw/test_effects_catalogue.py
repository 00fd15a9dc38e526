"""The effect catalogue (DESIGN.md section 8): injectable departures from the nominal model."""

from __future__ import annotations

import importlib
import math
import pkgutil

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from simhw import effects
from simhw.config import AXES, SimConfig, from_dict, to_dict, validate
from simhw.effects import Effect, catalogue, get, nominal, parse_spec

REQUIRED = {
    "none",
    "bearing_friction",
    "mount_resonance",
    "pickup_line",
    "flicker_noise",
    "offset_jumps",
    "gyro_cross_coupling",
    "scale_factor_error",
    "time_delay",
    "extra_damping",
}
#: Effects that act on a primary autocollimator, which only X and Y have.
AC_ONLY = {"mount_resonance", "flicker_noise", "offset_jumps", "time_delay"}
ALL = sorted(catalogue())
WITH_PARAMS = [n for n in ALL if catalogue()[n].params]


def _modules_defining_effect():
    names = set()
    for info in pkgutil.iter_modules(effects.__path__):
        module = importlib.import_module(f"{effects.__name__}.{info.name}")
        if isinstance(getattr(module, "EFFECT", None), Effect):
            names.add(info.name)
    return names


# --------------------------------------------------------------------------- discovery
def test_catalogue_holds_at_least_the_design_effects():
    assert REQUIRED <= set(catalogue())


def test_catalogue_is_every_module_in_the_package_that_defines_EFFECT():
    assert set(catalogue()) == _modules_defining_effect()


@pytest.mark.parametrize("name", ALL)
def test_each_effect_is_named_after_its_module(name):
    module = importlib.import_module(f"{effects.__name__}.{name}")
    assert module.EFFECT.name == name
    assert module.EFFECT is catalogue()[name]


def test_catalogue_is_sorted_by_name():
    assert list(catalogue()) == sorted(catalogue())


@pytest.mark.parametrize("name", ALL)
def test_each_effect_has_a_doc_and_consistent_parameters(name):
    eff = catalogue()[name]
    assert eff.doc.strip()
    names = [p.name for p in eff.params]
    assert len(names) == len(set(names))
    for p in eff.params:
        assert p.lo <= p.default <= p.hi, p.name
        if p.log:
            assert p.lo > 0, p.name
    if eff.params:
        assert eff.key_param in names
    else:
        assert eff.key_param is None


def test_get_returns_the_named_effect_and_rejects_unknown_names():
    assert get("time_delay") is catalogue()["time_delay"]
    with pytest.raises(ValueError, match="unknown effect 'warp_drive'") as exc:
        get("warp_drive")
    assert "bearing_friction" in str(exc.value)  # lists the known ones


# --------------------------------------------------------------------------- inject
@pytest.mark.parametrize("name", ALL)
def test_default_injection_returns_a_new_config_and_leaves_the_input_untouched(name):
    cfg = SimConfig()
    before = to_dict(cfg)
    out = catalogue()[name].inject(cfg, "X")
    assert isinstance(out, SimConfig)
    assert out is not cfg
    assert to_dict(cfg) == before
    if name == "none":
        assert to_dict(out) == before
    else:
        assert to_dict(out) != before
    validate(out)


@pytest.mark.parametrize("name", ALL)
def test_injected_config_shares_no_mutable_state_with_the_input(name):
    cfg = SimConfig()
    out = catalogue()[name].inject(cfg, "X")
    out.gyro["X"].pickoff_lines.append([1.0, 0.0])
    out.platform["X"].inertia_kg_m2 = 3.0
    out.pickup.append(None)
    assert to_dict(cfg) == to_dict(SimConfig())


@pytest.mark.parametrize("axis", ["X", "Y", "Z"])
def test_effects_act_on_the_requested_axis_only(axis):
    nom = nominal()
    out = catalogue()["extra_damping"].inject(nom, axis, damping_Nms=3.0)
    assert out.platform[axis].extra_damping_Nms == 3.0
    assert all(out.platform[a].extra_damping_Nms == 0.0 for a in AXES if a != axis)


def test_bearing_friction_turns_the_nominal_bearing_into_a_dahl_spring_of_the_given_stiffness():
    out = get("bearing_friction").inject(nominal(), "Y", stiffness_Nm_per_rad=800.0, To_Nm=0.02)
    b = out.bearing["Y"]
    assert b.model == "dahl" and b.To_Nm == 0.02
    assert b.eta_per_Nm * b.To_Nm**2 == pytest.approx(800.0)
    assert out.bearing["X"].model == "none"


def test_pickup_line_adds_a_line_on_the_axis_control_channel():
    out = get("pickup_line").inject(SimConfig(), "Y", freq_hz=200.0, amplitude_V=0.003)
    assert [(p.channel, p.freq_hz, p.amplitude_V) for p in out.pickup] == [
        ("ac_y_ctl", 200.0, 0.003)
    ]
    out_z = get("pickup_line").inject(SimConfig(), "Z")
    assert out_z.pickup[0].channel == "ac_z"


def test_scale_factor_error_on_Z_scales_the_azimuth_unit():
    cfg = SimConfig()
    out = get("scale_factor_error").inject(cfg, "Z", fraction=0.2)
    assert out.azimuth.scale_mV_per_urad == pytest.approx(1.2 * cfg.azimuth.scale_mV_per_urad)
    assert out.autocollimator == cfg.autocollimator


def test_gyro_cross_coupling_divides_h_over_c_by_the_factor():
    cfg = SimConfig()
    out = get("gyro_cross_coupling").inject(cfg, "Y", factor=4.0)
    assert out.gyro["Y"].viscous_coupling_h_over_c == pytest.approx(
        cfg.gyro["Y"].viscous_coupling_h_over_c / 4
    )


@pytest.mark.parametrize("name", sorted(AC_ONLY))
def test_autocollimator_effects_reject_the_Z_axis(name):
    with pytest.raises(ValueError, match=name):
        catalogue()[name].inject(SimConfig(), "Z")


@pytest.mark.parametrize("axis", ["W", "x", "XRD", ""])
def test_inject_rejects_an_unknown_axis(axis):
    with pytest.raises(ValueError, match="unknown axis"):
        catalogue()["extra_damping"].inject(SimConfig(), axis)


@pytest.mark.parametrize("name", ALL)
def test_inject_rejects_unknown_parameter_naming_it(name):
    with pytest.raises(ValueError) as exc:
        catalogue()[name].inject(SimConfig(), "X", warp_factor=1.0)
    msg = str(exc.value)
    assert name in msg and "'warp_factor'" in msg


@pytest.mark.parametrize("name", WITH_PARAMS)
@pytest.mark.parametrize("where", ["below", "above", "nan"])
def test_inject_rejects_values_outside_the_prior_naming_parameter_and_range(name, where):
    eff = catalogue()[name]
    p = eff.params[0]
    value = {"below": p.lo - abs(p.lo) - 1.0, "above": p.hi + abs(p.hi) + 1.0, "nan": math.nan}[
        where
    ]
    with pytest.raises(ValueError) as exc:
        eff.inject(SimConfig(), "X", **{p.name: value})
    msg = str(exc.value)
    assert p.name in msg and str(p.lo) in msg and str(p.hi) in msg


@settings(max_examples=100, deadline=None)
@given(st.data())
def test_any_in_prior_injection_gives_a_valid_config(data):
    name = data.draw(st.sampled_from(WITH_PARAMS))
    eff = catalogue()[name]
    axis = data.draw(st.sampled_from(["X", "Y"] if name in AC_ONLY else list(AXES)))
    values = {p.name: data.draw(st.floats(p.lo, p.hi)) for p in eff.params}
    out = eff.inject(nominal(), axis, **values)
    validate(out)
    assert from_dict(to_dict(out)) == out  # survives a round trip through the TOML-friendly form


# --------------------------------------------------------------------------- parse_spec
def test_parse_spec_reads_name_and_values():
    eff, values, axis = parse_spec("pickup_line:freq_hz=200,amplitude_V=0.003")
    assert eff is get("pickup_line")
    assert values == {"freq_hz": 200.0, "amplitude_V": 0.003}
    assert axis == "X"


def test_parse_spec_reads_axis_and_tolerates_spaces():
    eff, values, axis = parse_spec(" time_delay : delay_s = 0.004 , axis = y ")
    assert eff.name == "time_delay" and values == {"delay_s": 0.004} and axis == "Y"


@pytest.mark.parametrize("spec", ["none", "none:", "bearing_friction"])
def test_parse_spec_without_values_uses_the_defaults(spec):
    eff, values, axis = parse_spec(spec)
    assert values == {} and axis == "X"


def test_parsed_spec_injects():
    eff, values, axis = parse_spec("mount_resonance:freq_hz=80,damping=0.1,axis=Y")
    out = eff.inject(SimConfig(), axis, **values)
    assert (out.autocollimator["Y"].mount_freq_hz, out.autocollimator["Y"].mount_damping) == (
        80.0,
        0.1,
    )


@pytest.mark.parametrize(
    "spec, fragments",
    [
        ("warp_drive:x=1", ["unknown effect", "'warp_drive'"]),
        ("", ["unknown effect", "''"]),
        ("pickup_line:freq_hz", ["pickup_line", "key=value", "'freq_hz'"]),
        ("pickup_line:freq_hz=fast", ["pickup_line", "freq_hz", "'fast'", "not a number"]),
        ("pickup_line:freq_hz=200;amplitude_V=1", ["pickup_line", "not a number"]),
    ],
)
def test_bad_spec_raises_value_error_saying_what_is_wrong(spec, fragments):
    with pytest.raises(ValueError) as exc:
        parse_spec(spec)
    for frag in fragments:
        assert frag in str(exc.value)


def test_spec_with_unknown_parameter_is_rejected_on_injection():
    eff, values, axis = parse_spec("pickup_line:freq=200")
    with pytest.raises(ValueError, match="unknown parameter 'freq'"):
        eff.inject(SimConfig(), axis, **values)


# --------------------------------------------------------------------------- nominal
def test_nominal_turns_every_bearing_model_off_and_nothing_else():
    cfg = SimConfig()
    nom = nominal(cfg)
    assert all(nom.bearing[a].model == "none" for a in AXES)
    assert all(cfg.bearing[a].model == "dahl" for a in AXES)  # input untouched
    a, b = to_dict(cfg), to_dict(nom)
    for axis in AXES:
        del a["bearing"][axis]["model"], b["bearing"][axis]["model"]
    assert a == b


def test_nominal_without_argument_starts_from_the_thesis_rig():
    expected = SimConfig()
    for b in expected.bearing.values():
        b.model = "none"
    assert nominal() == expected


def test_nominal_keeps_other_changes_of_its_input():
    cfg = from_dict({"site": {"latitude_deg": 10.0}, "bearing": {"Y": {"model": "spring"}}})
    nom = nominal(cfg)
    assert nom.site.latitude_deg == 10.0
    assert nom.bearing["Y"].model == "none"
    assert cfg.bearing["Y"].model == "spring"
