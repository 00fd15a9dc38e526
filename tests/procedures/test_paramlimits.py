"""``procedures.paramlimits``: the limits declared on the procedures' ``Params`` fields check
values with messages naming the parameter, the value and the limit, and describe themselves for
``fbs run NAME --help`` in words that give the bounds back exactly."""

from __future__ import annotations

import dataclasses
import math
import re
import typing
from dataclasses import dataclass, field
from typing import Annotated, Any

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from procedures.calibrations import catalogue
from procedures.paramlimits import (
    Each,
    ExistingFile,
    OneOf,
    ParamLimitError,
    Range,
    Validator,
    above,
    at_least,
    check_limits,
    declared,
    describe_limits,
)
from procedures.params import parse_params

# the machine may be loaded: no per-example deadline
FAST = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])

bounds = st.one_of(
    st.none(), st.integers(-(10**6), 10**6), st.floats(allow_nan=False, allow_infinity=False)
)
units = st.sampled_from(["", "V", "urad/s", "urad/s/V", "N m"])


@st.composite
def ranges(draw) -> Range:
    lo, hi = draw(bounds), draw(bounds)
    lo_open, hi_open = draw(st.booleans()), draw(st.booleans())
    assume(lo is not None or hi is not None)
    if lo is not None and hi is not None:
        lo, hi = min(lo, hi), max(lo, hi)
        assume(lo < hi or not (lo_open or hi_open))
    return Range(lo, hi, lo_open=lo_open, hi_open=hi_open, units=draw(units))


def near(r: Range) -> st.SearchStrategy[float]:
    """Values on, just inside and just outside each bound, and anywhere."""
    edges = [b for b in (r.lo, r.hi) if b is not None]
    close = [
        x
        for b in edges
        for x in (float(b), math.nextafter(b, -math.inf), math.nextafter(b, math.inf))
    ]
    return st.one_of(st.sampled_from(close), st.floats(allow_nan=False, allow_infinity=False))


def inside(r: Range, v: float) -> bool:
    """The interval, written out as the oracle."""
    above_lo = r.lo is None or (v > r.lo if r.lo_open else v >= r.lo)
    below_hi = r.hi is None or (v < r.hi if r.hi_open else v <= r.hi)
    return above_lo and below_hi


_NUM = r"(\S+)"


def parse(description: str) -> tuple[float | None, float | None, bool, bool, str]:
    """``describe()`` read back: (lo, hi, lo_open, hi_open, units)."""
    if m := re.fullmatch(rf"{_NUM}\.\.{_NUM}(?: (.+))?", description):
        return float(m[1]), float(m[2]), False, False, m[3] or ""
    if m := re.fullmatch(rf"(>=?) {_NUM} and (<=?) {_NUM}(?: (.+))?", description):
        return float(m[2]), float(m[4]), m[1] == ">", m[3] == "<", m[5] or ""
    m = re.fullmatch(rf"([<>]=?) {_NUM}(?: (.+))?", description)
    assert m, description
    bound, is_open, rest = float(m[2]), "=" not in m[1], m[3] or ""
    return (
        (bound, None, is_open, False, rest)
        if m[1][0] == ">"
        else (None, bound, False, is_open, rest)
    )


# ---------------------------------------------------------------------------- Range
@FAST
@given(st.data())
def test_a_range_passes_a_value_inside_and_names_value_and_limit_outside(data):
    r = data.draw(ranges())
    v = data.draw(near(r))
    why = r.problem(v, "x")
    if inside(r, v):
        assert why == ""
        r.check(v, "x", "proc")
    else:
        assert why.startswith(
            f"x = {v}{' ' + r.units if r.units else ''} must be {r.describe()}"
        ), why
        with pytest.raises(ParamLimitError, match=re.escape(f"proc: {why}")):
            r.check(v, "x", "proc")


@FAST
@given(ranges())
def test_a_ranges_description_gives_its_bounds_back(r):
    lo, hi, lo_open, hi_open, u = parse(r.describe())
    assert (lo, hi, u) == (r.lo, r.hi, r.units)
    # an absent bound is neither open nor closed: only a present one's openness is stated
    assert (lo_open, hi_open) == (r.lo_open and r.lo is not None, r.hi_open and r.hi is not None)


@FAST
@given(ranges(), st.sampled_from([math.inf, -math.inf, math.nan, "3", None, True, [1.0]]))
def test_a_range_refuses_what_is_not_a_finite_number_saying_so(r, v):
    why = r.problem(v, "x")
    assert why.startswith("x = ") and r.describe() in why
    assert ("must be finite" in why) if isinstance(v, float) else ("must be a number" in why)


@pytest.mark.parametrize(
    "r, text",
    [
        (Range(1, 50), "1..50"),
        (Range(0.05, 8.0, units="V"), "0.05..8 V"),
        (above(0), "> 0"),
        (at_least(8), ">= 8"),
        (Range(None, 1e3, hi_open=True), "< 1000"),
        (Range(0, 1e3, lo_open=True, hi_open=True, units="urad/s/V"), "> 0 and < 1000 urad/s/V"),
        (Range(0.0, 10.0, hi_open=True, units="urad/s"), ">= 0 and < 10 urad/s"),
        (Range(2.5, 2.5), "2.5..2.5"),
    ],
)
def test_range_descriptions_read_as_the_messages_always_have(r, text):
    assert r.describe() == text


@pytest.mark.parametrize("kw", [{}, {"lo": 2, "hi": 1}, {"lo": 1, "hi": 1, "lo_open": True}])
def test_a_range_that_holds_no_value_is_refused_when_declared(kw):
    with pytest.raises(ValueError, match="Range"):
        Range(**kw)


def test_a_note_says_why_in_the_message_only():
    r = Range(0.05, 8.0, units="V", note="the pickoff's linear range is about +-6 V")
    assert r.problem(9.0, "delta_pickoff_V") == (
        "delta_pickoff_V = 9.0 V must be 0.05..8 V (the pickoff's linear range is about +-6 V)"
    )
    assert r.describe() == "0.05..8 V"


# ---------------------------------------------------------------------------- OneOf, Each
@FAST
@given(
    st.lists(
        st.text(min_size=1, max_size=4, alphabet="XYZRD"), min_size=1, max_size=5, unique=True
    ),
    st.text(max_size=4, alphabet="XYZRDQ"),
)
def test_one_of_passes_a_choice_and_names_anything_else(choices, v):
    o = OneOf(*choices)
    assert o.describe().removeprefix("one of ").split(", ") == choices
    why = o.problem(v, "axis")
    assert (why == "") == (v in choices)
    if why:
        assert why == f"axis = {v!r} must be {o.describe()}"


def test_one_of_refuses_an_unhashable_value_by_name():
    assert OneOf("X", "Y").problem(["X"], "axis") == "axis = ['X'] must be one of X, Y"


@FAST
@given(
    st.lists(
        st.floats(allow_nan=False, allow_infinity=False, min_value=-100, max_value=100), max_size=6
    )
)
def test_each_names_the_first_element_outside_by_its_index(values):
    e = Each(Range(0, 90, units="deg"), nonempty=True)
    why = e.problem(values, "tilts_deg")
    bad = [i for i, v in enumerate(values) if not 0 <= v <= 90]
    if not values:
        assert why == "tilts_deg = [] must be non-empty, each 0..90 deg"
    elif bad:
        assert why == f"tilts_deg[{bad[0]}] = {values[bad[0]]} deg must be 0..90 deg"
    else:
        assert why == ""


def test_each_checks_a_mappings_keys_and_values():
    e = Each(Range(0, 1e3, lo_open=True, hi_open=True), keys=OneOf("X", "Y"))
    assert e.describe() == "keys one of X, Y; values > 0 and < 1000"
    assert e.problem({"X": 31.6, "Y": 33.4}, "kto") == ""
    assert e.problem({"X": 0}, "kto") == "kto X = 0 must be > 0 and < 1000"
    assert e.problem({"Q": 31.6}, "kto") == "kto key = 'Q' must be one of X, Y"
    assert e.problem("X", "kto").startswith("kto = 'X' must be a list or mapping")


# ---------------------------------------------------------------------------- declared on a dataclass
@dataclass
class P:
    n: Annotated[int, Range(1, 50)] = 3
    lag: Annotated[float | None, above(0)] = None
    chans: Annotated[list[str], Each(OneOf("X", "Y"))] = field(default_factory=lambda: ["X"])
    free: float = 1.0

    def __post_init__(self) -> None:
        check_limits(self, "proc")


def test_declared_limits_are_found_none_is_not_checked_and_the_bare_types_stay_plain():
    assert list(declared(P)) == ["n", "lag", "chans"]
    assert describe_limits(P) == {"n": "1..50", "lag": "> 0", "chans": "each one of X, Y"}
    P(lag=None)
    with pytest.raises(ParamLimitError, match=r"^proc: n = 51 must be 1\.\.50$"):
        P(n=51)
    with pytest.raises(ParamLimitError, match=r"^proc: chans\[1\] = 'Z' must be one of X, Y$"):
        P(chans=["X", "Z"])
    # procedures.paramtypes and mypy see the type without its limit
    assert typing.get_type_hints(P) == {
        "n": int,
        "lag": float | None,
        "chans": list[str],
        "free": float,
    }


# ---------------------------------------------------------------------------- every procedure
def _outside(v: Validator, default: Any, integer: bool) -> list[Any]:
    """Values that break ``v`` (a field's default shows a list's or mapping's shape)."""
    if isinstance(v, Range):
        step = (lambda b, d: b + d) if integer else (lambda b, d: math.nextafter(b, d * math.inf))
        out = []
        if v.lo is not None:
            out.append(v.lo if v.lo_open else step(v.lo, -1))
        if v.hi is not None:
            out.append(v.hi if v.hi_open else step(v.hi, 1))
        return out
    if isinstance(v, OneOf):
        return ["no such choice"]
    if isinstance(v, ExistingFile):
        return ["/no/such/file.h5", "/", "/dev/null"]
    assert isinstance(v, Each), v
    out = [[]] if v.nonempty else []
    if isinstance(default, dict) or v.keys is not None:
        out += [{"no such key": 1.0}] if v.keys is not None else []
        key = next(iter(v.keys.choices)) if isinstance(v.keys, OneOf) else "X"
        out += [{key: bad} for bad in _outside(v.item, None, False)] if v.item is not None else []
    elif v.item is not None:
        out += [[bad] for bad in _outside(v.item, None, False)]
    return out


CASES = [
    (proc_name, f.name, v, bad)
    for proc_name, proc in catalogue().items()
    for f in dataclasses.fields(proc.Params)
    for v in declared(proc.Params).get(f.name, ())
    for bad in _outside(
        v, proc.Params().__dict__[f.name], typing.get_type_hints(proc.Params)[f.name] is int
    )
]


def test_every_parameter_of_every_procedure_declares_a_limit_and_its_defaults_are_within_them():
    for name, proc in catalogue().items():
        undeclared = [
            f.name for f in dataclasses.fields(proc.Params) if f.name not in declared(proc.Params)
        ]
        assert not undeclared, f"{name}: no declared limit on {undeclared}"
        check_limits(proc.Params(), name)


@pytest.mark.parametrize("name", sorted(catalogue()))
def test_a_rate_the_adc_would_refuse_is_refused_before_the_rig_opens(name):
    proc = catalogue()[name]
    with pytest.raises(ParamLimitError, match=r"rate_hz = 1000000.0 Hz must be 1\.\.20000 Hz"):
        parse_params(proc, ["rate_hz=1e6"], None)
    with pytest.raises(ParamLimitError, match=r"rate_hz = 0.5 Hz must be 1\.\.20000 Hz"):
        parse_params(proc, ["rate_hz=0.5"], None)


@pytest.mark.parametrize(
    "proc_name, field_name, validator, bad", CASES, ids=[f"{c[0]}-{c[1]}-{c[3]!r}" for c in CASES]
)
def test_every_declared_limit_refuses_a_value_just_outside_naming_it(
    proc_name, field_name, validator, bad
):
    proc = catalogue()[proc_name]
    with pytest.raises(ParamLimitError) as exc:
        proc.Params(**{field_name: bad})
    text = str(exc.value)
    assert text.startswith(f"{proc_name}: {field_name}") and " must be " in text, text
    # the limit broken is stated as help states it (an element's by the element's own limit)
    inner = (
        validator.item
        if isinstance(validator, Each) and bad and validator.item is not None
        else validator
    )
    if isinstance(bad, dict) and "no such key" in bad:
        inner = validator.keys
    assert inner is not None and inner.describe() in text, text


@pytest.mark.parametrize(
    "proc_name, spec, message",
    [
        ("stopwatch", "repetitions=51", "stopwatch: repetitions = 51 must be 1..4"),
        (
            "stopwatch",
            "delta_pickoff_V=9",
            "delta_pickoff_V = 9 V must be 0.05..8 V (the pickoff's linear range",
        ),
        (
            "stopwatch",
            'kto_urad_per_s_per_V={"X": 0}',
            "kto_urad_per_s_per_V X = 0 urad/s/V must be > 0 and < 1000 urad/s/V",
        ),
        ("stopwatch", 'channels=["X", "Q"]', "channels[1] = 'Q' must be one of X, Y, Z, XRD"),
        ("stopwatch", "channels=[]", "channels = [] must be non-empty"),
        (
            "earth-rate",
            "n_spindle=2",
            "earth-rate: n_spindle = 2 must be 4..36 (the spindle angles per tilt)",
        ),
        ("earth-rate", "tilts_deg=[0, 95, 45]", "tilts_deg[1] = 95 deg must be 0..90 deg"),
        (
            "hysteresis",
            "axis=Z",
            "axis = 'Z' must be one of X, Y (the others have no instrumentation autocollimator",
        ),
        (
            "hysteresis",
            "updates_per_cycle=3",
            "updates_per_cycle = 3 must be >= 8 (fewer is too coarse a sine)",
        ),
        ("drift", "n_chunks=0", "drift: n_chunks = 0 must be 1..1000"),
        ("survey", "settle_s=-1", "survey: settle_s = -1 must be >= 0"),
    ],
)
def test_fbs_run_params_out_of_their_limits_are_refused_in_the_usual_words(
    proc_name, spec, message
):
    with pytest.raises(ValueError) as exc:
        parse_params(catalogue()[proc_name], [spec], None)
    assert message in str(exc.value)


def test_the_run_help_states_every_declared_limit():
    from fbs.procedure_help import parameter_help

    for name, proc in catalogue().items():
        text = parameter_help(name, width=1000)
        for field_name, limit in describe_limits(proc.Params).items():
            assert re.search(rf"^  {field_name} = .*limits: {re.escape(limit)}\)$", text, re.M), (
                field_name,
                text,
            )
