"""``procedures.paramtypes``: --param values checked against the declared types before a
procedure's Params sees them (issue 19 item 5)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import pytest
from hypothesis import given
from hypothesis import strategies as st

from procedures.calibrations import catalogue
from procedures.params import parse_params
from procedures.paramtypes import MAX_SECONDS, ParamTypeError, check


@dataclass
class P:
    n: int = 1
    x: float = 1.0
    hold_s: float = 1.0
    name: str = "a"
    flag: bool = False
    maybe: float | None = None
    chans: list[str] = field(default_factory=list)
    levels: list[float] = field(default_factory=list)
    kto: dict[str, float] = field(default_factory=dict)


@pytest.mark.parametrize(
    "data, message",
    [
        ({"n": 1.5}, "n = 1.5: must be an integer"),
        ({"n": True}, "n = True: must be an integer"),
        ({"x": math.nan}, "must be a finite number"),
        ({"x": math.inf}, "must be a finite number"),
        ({"x": "3"}, "must be a number"),
        ({"x": False}, "must be a number"),
        ({"hold_s": 1e300}, "longest duration"),
        ({"name": 3}, "must be a string"),
        ({"flag": 1}, "must be true or false"),
        ({"maybe": math.nan}, "must be a finite number"),
        ({"chans": ["X", 1]}, "element 1 (1) must be a string"),
        ({"chans": "X"}, "must be a list"),
        ({"levels": [1.0, math.inf]}, "element 1"),
        ({"kto": {"X": math.nan}}, "entry 'X'"),
        ({"kto": [1.0]}, "must be a mapping"),
    ],
)
def test_a_value_that_does_not_fit_its_type_is_named(data, message):
    with pytest.raises(ParamTypeError, match="proc: parameter") as exc:
        check(P, data, "proc")
    assert message in str(exc.value)


def test_values_of_the_declared_types_pass():
    check(
        P,
        {
            "n": 3,
            "x": 2,
            "hold_s": MAX_SECONDS,
            "name": "b",
            "flag": True,
            "maybe": None,
            "chans": ["X"],
            "levels": [1, 2.5],
            "kto": {"X": 31.6},
            "unknown": object(),
        },
        "proc",
    )


@given(
    st.one_of(
        st.floats(allow_nan=True, allow_infinity=True),
        st.integers(),
        st.booleans(),
        st.text(max_size=3),
        st.none(),
        st.lists(st.integers(), max_size=2),
    )
)
def test_any_json_value_either_fits_a_float_or_is_refused_by_name(value):
    try:
        check(P, {"x": value}, "proc")
    except ParamTypeError as exc:
        assert "parameter x" in str(exc)
    else:
        assert (
            not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)
        )


@pytest.mark.parametrize(
    "name, spec, message",
    [
        ("stopwatch", "repetitions=1.5", "repetitions = 1.5: must be an integer"),
        ("stopwatch", "repetitions=true", "must be an integer"),
        ("stopwatch", "hold_s=Infinity", "must be a finite number"),
        ("stopwatch", "kg_tolerance=NaN", "must be a finite number"),
        ("stopwatch", 'kto_urad_per_s_per_V={"X": 0}', "kto_urad_per_s_per_V X = 0"),
        ("earth-rate", "n_spindle=5.5", "n_spindle = 5.5: must be an integer"),
    ],
)
def test_fbs_run_params_are_refused_before_the_procedure_exists(name, spec, message):
    with pytest.raises(ValueError) as exc:
        parse_params(catalogue()[name], [spec], None)
    assert message in str(exc.value)
