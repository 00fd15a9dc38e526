"""Typed step results (issue 40 item 2): every procedure's step result reads back from its
JSON as the same value (hypothesis), floats kept to the type's significant digits; a result too
large for its event is refused with the procedure, the step, its size and the limit."""

from __future__ import annotations

import dataclasses
import json
import math
from typing import Any, get_type_hints

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from daq.runfile import TEXT_BYTES
from procedures.calibrations import catalogue
from procedures.procedure import StepResultTooLarge
from procedures.runner import step_done_text
from procedures.stepresult import StepResult, StepResultError, round_sig


def _result_types() -> list[type[StepResult]]:
    """Every step result type the catalogue's procedures name in their default plans, and the
    ones those nest."""
    found: dict[str, type[StepResult]] = {}
    for proc in catalogue().values():
        for step in proc().plan():
            found[step.result.__qualname__] = step.result
    return sorted(found.values(), key=lambda t: t.__qualname__)


TYPES = _result_types()


def _every_field(tp: type[StepResult]) -> st.SearchStrategy[StepResult]:
    """Instances of ``tp`` with every field drawn (``st.builds`` alone leaves defaults be)."""
    hints = get_type_hints(tp)
    return st.builds(tp, **{f.name: st.from_type(hints[f.name]) for f in dataclasses.fields(tp)})


def test_every_procedure_names_its_step_results():
    names = {t.__name__ for t in TYPES}
    assert {"InMode3", "Station", "ChannelRun", "Probe", "Sweep", "Recorded"} <= names


@pytest.mark.parametrize("tp", TYPES, ids=lambda t: t.__name__)
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_a_step_result_reads_back_from_its_json(tp, data):
    r = data.draw(_every_field(tp), label=tp.__name__)
    text = json.dumps(r.to_json())
    back = tp.from_json(json.loads(text))
    assert type(back) is tp
    # the JSON is the value, to the type's digits: written again, the same text
    assert json.dumps(back.to_json()) == text
    for f in dataclasses.fields(tp):
        _close(getattr(r, f.name), getattr(back, f.name), tp.digits)


def _close(a: Any, b: Any, digits: int) -> None:
    """``b`` is ``a`` with its floats to ``digits`` significant digits, its lists as tuples."""
    if isinstance(a, float):
        assert isinstance(b, float)
        if math.isnan(a):
            assert math.isnan(b)
        else:
            assert b == round_sig(a, digits)
            assert b == pytest.approx(a, rel=10.0 ** (1 - digits), abs=0.0) or a == b
    elif isinstance(a, StepResult):
        for f in dataclasses.fields(a):
            _close(getattr(a, f.name), getattr(b, f.name), digits)
    elif isinstance(a, tuple | list):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _close(x, y, digits)
    elif isinstance(a, dict):
        assert a.keys() == b.keys()
        for k in a:
            _close(a[k], b[k], digits)
    else:
        assert a == b and type(a) is type(b)


def test_a_result_of_another_shape_is_refused_by_name():
    station = next(t for t in TYPES if t.__name__ == "Station")
    with pytest.raises(StepResultError, match="Station: unknown field"):
        station.from_json({"tilt": 0.0, "spindle": 0.0, "V": {}, "volts": 1})
    with pytest.raises(StepResultError, match="Station"):
        station.from_json({"tilt": "level", "spindle": 0.0, "V": {}})


def test_an_oversize_result_is_refused_with_its_procedure_step_size_and_limit():
    done = {"step": "channel X", "result": {"text": "x" * TEXT_BYTES}}
    size = len(json.dumps(done, separators=(",", ":")).encode())
    with pytest.raises(StepResultTooLarge) as info:
        step_done_text("stopwatch", done)
    e = info.value
    assert (e.procedure, e.step, e.size, e.limit) == ("stopwatch", "channel X", size, TEXT_BYTES)
    assert f"stopwatch: step 'channel X': its result is {size} bytes" in str(e)
    assert f"({TEXT_BYTES})" in str(e)
    # one byte under the limit is written as it is
    fits = {"step": "s", "result": {"text": ""}}
    fits["result"]["text"] = "x" * (TEXT_BYTES - len(json.dumps(fits, separators=(",", ":"))))
    assert len(step_done_text("p", fits).encode()) == TEXT_BYTES
