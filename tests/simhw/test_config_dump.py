"""``simhw.config_dump.dump_config``: a SimConfig back to the TOML ``load_config`` reads.

The round trip ``from_dict(tomllib.loads(dump_config(cfg))) == cfg`` must hold for the configs
the model-gap workflow writes (catalogue effects at any parameters of their priors, a unit's
nuisance noise levels and pickoff lines), for any float (repr precision) and any string, and for
every field of every section, including fields added to ``simhw.config`` later: the field test
walks the dataclasses, it names no key.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from functools import cache
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from simhw import effects
from simhw.config import (
    AC_AXES,
    AXES,
    BEARING_MODELS,
    GYRO_CHANNELS,
    ConfigError,
    PickupLine,
    SimConfig,
    from_dict,
    load_config,
    to_dict,
    validate,
)
from simhw.config_dump import dump_config

FAST = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@cache
def _catalogue() -> dict[str, effects.Effect]:
    return {n: e for n, e in effects.catalogue().items() if e.params}


def _round_trip(cfg: SimConfig, base: SimConfig | None = None) -> SimConfig:
    return from_dict(tomllib.loads(dump_config(cfg, base)), base=base)


def _param_value(draw: st.DrawFn, p: effects.Param) -> float:
    if p.log and p.lo > 0:
        v = math.exp(draw(st.floats(math.log(p.lo), math.log(p.hi))))
    else:
        v = draw(st.floats(p.lo, p.hi))
    return min(max(v, p.lo), p.hi)  # exp(log(x)) may step a last bit outside


@st.composite
def refined_configs(draw: st.DrawFn) -> SimConfig:
    """The nominal rig (or the data sheet's) with random catalogue effects on random axes and a
    unit's nuisance: autocollimator NEA and 1/f corner, pickoff white level and lines."""
    cfg = draw(st.sampled_from([effects.nominal(), SimConfig()]))
    names = draw(st.lists(st.sampled_from(sorted(_catalogue())), max_size=4))
    for name in names:
        eff = _catalogue()[name]
        axis = draw(st.sampled_from(AXES))
        values = {p.name: _param_value(draw, p) for p in eff.params if draw(st.booleans())}
        try:
            cfg = eff.inject(cfg, axis, **values)
        except (
            ValueError,
            ConfigError,
        ):  # an effect that axis has no place for (no autocollimator on Z)
            continue
    for ax in draw(st.lists(st.sampled_from(AC_AXES), max_size=2, unique=True)):
        ac = cfg.autocollimator[ax]
        ac.nea_urad *= draw(st.floats(0.6, 1.6))
        ac.flicker_corner_hz = draw(st.floats(1.5, 5.0))
    for ch in draw(st.lists(st.sampled_from(GYRO_CHANNELS), max_size=2, unique=True)):
        g = cfg.gyro[ch]
        white = (g.pickoff_noise_rms_urad**2 - sum(a * a / 2 for _, a in g.pickoff_lines)) * draw(
            st.floats(0.25, 4.0)
        )
        lines = [
            [f + draw(st.floats(-1.0, 1.0)), a * draw(st.floats(0.5, 2.0))]
            for f, a in g.pickoff_lines
        ]
        if draw(st.booleans()):
            lines = lines[: draw(st.integers(0, len(lines)))]
        g.pickoff_lines = lines
        g.pickoff_noise_rms_urad = math.sqrt(max(white, 0.0) + sum(a * a / 2 for _, a in lines))
    validate(cfg)
    return cfg


@FAST
@given(refined_configs())
def test_a_refined_config_reads_back_equal(cfg):
    text = dump_config(cfg)
    assert from_dict(tomllib.loads(text)) == cfg


@FAST
@given(refined_configs(), refined_configs())
def test_an_overlay_on_another_base_reads_back_equal_on_that_base(cfg, base):
    assert _round_trip(cfg, base) == cfg


def test_the_thesis_rig_is_an_empty_file_and_only_changes_are_written():
    assert dump_config(SimConfig()) == ""
    cfg = effects.get("bearing_friction").inject(effects.nominal(), "X", stiffness_Nm_per_rad=600.0)
    data = tomllib.loads(dump_config(cfg))
    assert data["bearing"]["X"] == {
        "eta_per_Nm": 600.0 / 0.016**2
    }  # model "dahl" as the data sheet
    assert data["bearing"]["Y"] == {"model": "none"} and data["bearing"]["Z"] == {"model": "none"}
    assert set(data) == {"bearing"}


def test_the_layout_is_the_one_load_config_reads(tmp_path):
    cfg = effects.get("pickup_line").inject(effects.nominal(), "Y", freq_hz=60.0, amplitude_V=0.005)
    cfg.site.latitude_deg = 0.1 + 0.2  # 0.30000000000000004: repr precision
    cfg.gyro["XRD"].pickoff_lines = [[70.1, 2.5], [102.0, 4.0]]
    text = dump_config(cfg, header="refined model\n\nof run.h5")
    assert text.startswith("# refined model\n#\n# of run.h5\n")
    for table in ("[site]", "[bearing.X]", "[gyro.XRD]", "[[pickup]]"):
        assert f"\n{table}\n" in text
    assert "latitude_deg = 0.30000000000000004" in text
    assert "pickoff_lines = [[70.1, 2.5], [102.0, 4.0]]" in text
    path = tmp_path / "refined.toml"
    path.write_text(text)
    assert load_config(path) == cfg


@settings(max_examples=100, deadline=None)
@given(st.text(max_size=40))
def test_any_header_is_comments_only(header):
    cfg = effects.get("time_delay").inject(SimConfig(), "Y", delay_s=0.003)
    text = dump_config(cfg, header=header)
    assert from_dict(tomllib.loads(text)) == cfg
    n = len(header.splitlines())
    assert all(line.startswith("#") for line in text.splitlines()[:n])


def test_removing_every_pickup_line_is_written_as_an_empty_array():
    base = effects.get("pickup_line").inject(SimConfig(), "X")
    data = tomllib.loads(dump_config(SimConfig(), base))
    assert data == {"pickup": []}
    assert _round_trip(SimConfig(), base) == SimConfig()


@settings(max_examples=200, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=20))
def test_any_float_and_any_string_read_back_exactly(x, text):
    cfg = SimConfig()
    cfg.gyro["Z"].fixed_drift_urad_per_s = x  # no range: any finite float is valid
    cfg.pickup = [PickupLine(text, 1.5, 0.0)]  # the channel is free text to the config
    back = _round_trip(cfg)
    assert back.gyro["Z"].fixed_drift_urad_per_s == x
    assert math.copysign(1.0, back.gyro["Z"].fixed_drift_urad_per_s) == math.copysign(1.0, x)
    assert back.pickup[0].channel == text


def test_numpy_scalars_are_written_as_plain_numbers():
    np = pytest.importorskip("numpy")
    cfg = SimConfig()
    cfg.autocollimator["X"].nea_urad = np.float64(0.5)
    cfg.gyro["X"].pickoff_lines = [[np.float64(70.5), np.float32(2.5)]]
    cfg.sampling.oversample = np.int64(4)
    text = dump_config(cfg)
    assert "np." not in text
    back = _round_trip(cfg)
    assert back.autocollimator["X"].nea_urad == 0.5 and back.sampling.oversample == 4
    assert back.gyro["X"].pickoff_lines == [[70.5, 2.5]]


# --------------------------------------------------------------------- every field, by walking them
def _sections(cfg: SimConfig) -> list[tuple[tuple[str, ...], Any]]:
    """Every (path, dataclass instance) of the config: plain sections, keyed sections' entries
    and list sections' items, as the dataclasses declare them (no key named here)."""
    out: list[tuple[tuple[str, ...], Any]] = []
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        if dataclasses.is_dataclass(value):
            out.append(((f.name,), value))
        elif isinstance(value, dict):
            out += [((f.name, k), v) for k, v in value.items() if dataclasses.is_dataclass(v)]
        elif isinstance(value, list):
            out += [
                ((f.name, str(i)), v) for i, v in enumerate(value) if dataclasses.is_dataclass(v)
            ]
    return out


def _another(f: dataclasses.Field, current: Any) -> Any:
    """A value of the field's type, different from ``current`` and inside its declared range
    where it has one (``simhw.config._f``'s metadata)."""
    if isinstance(current, bool):
        return not current
    if isinstance(current, int):
        return current + 1
    if isinstance(current, float):
        lo, hi = f.metadata.get("lo"), f.metadata.get("hi")
        if hi is not None:
            return (
                (current + hi) / 2
                if current != hi
                else (current + (lo if lo is not None else hi - 1.0)) / 2
            )
        return current * 1.25 + 0.5 if current >= 0 else current * 0.75
    if isinstance(current, str):
        return (
            next((m for m in BEARING_MODELS if m != current), "")
            if current in BEARING_MODELS
            else current + "-changed"
        )
    if isinstance(current, list):
        return (
            [*current, [333.0, 0.5]]
            if all(isinstance(x, list) for x in current)
            else [*current, 1.0]
        )
    raise AssertionError(f"a field of a type this test does not know: {f.name} = {current!r}")


def _fields_of_every_section() -> list[tuple[tuple[str, ...], str]]:
    cfg = SimConfig()
    cfg.pickup = [PickupLine("ac_x_ctl", 200.0, 0.003)]  # so the list section has an item to walk
    return [(path, f.name) for path, obj in _sections(cfg) for f in dataclasses.fields(obj)]


@pytest.mark.parametrize(
    ("path", "name"),
    _fields_of_every_section(),
    ids=lambda v: ".".join(v) if isinstance(v, tuple) else v,
)
def test_every_field_of_every_section_is_written_and_read_back(path, name):
    base = SimConfig()
    base.pickup = [PickupLine("ac_x_ctl", 200.0, 0.003)]
    cfg = base.copy()
    obj = dict(_sections(cfg))[path]
    f = next(f for f in dataclasses.fields(obj) if f.name == name)
    new = _another(f, getattr(obj, name))
    setattr(obj, name, new)
    data = tomllib.loads(dump_config(cfg, base))
    # only that value is written, where from_dict looks for it
    if path[0] == "pickup":
        assert data == {"pickup": [to_dict(cfg)["pickup"][0]]}
    else:
        node: Any = data
        for p in path:
            node = node[p]
        assert node == {name: new}
        assert len(data) == 1
    try:
        validate(cfg)
    except ConfigError:
        pytest.skip(
            f"{'.'.join(path)}.{name} = {new!r} is outside what validate allows; written and parsed only"
        )
    assert from_dict(data, base=base) == cfg


def test_every_float_field_keeps_repr_precision():
    """Each float field at a value with a full 17-digit repr, all at once, reads back exactly."""
    cfg = SimConfig()
    for _, obj in _sections(cfg):
        for f in dataclasses.fields(obj):
            v, hi = getattr(obj, f.name), f.metadata.get("hi")
            if isinstance(v, float) and v != 0.0:
                setattr(
                    obj,
                    f.name,
                    math.nextafter(v, -math.inf if hi is not None and v >= hi else math.inf),
                )
    assert _round_trip(cfg) == cfg
