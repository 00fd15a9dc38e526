"""Every ``--json`` result against ``docs/schema/run-summary.schema.json`` (issue 37, acceptance
A), plus what a JSON Schema cannot say: a figure, its interval and its ``resolved`` name the same
channels, and a null figure is never resolved."""

from __future__ import annotations

import functools
import json
from pathlib import Path
from typing import Any

import jsonschema

SCHEMA = Path(__file__).resolve().parent.parent / "docs" / "schema" / "run-summary.schema.json"


@functools.cache
def validator() -> jsonschema.Draft202012Validator:
    schema = json.loads(SCHEMA.read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def assert_valid_result(out: dict[str, Any]) -> None:
    """``out`` (a parsed ``--json`` object) follows the schema; per-channel shapes agree."""
    out = json.loads(json.dumps(out, allow_nan=False))  # strict JSON: no NaN, only JSON types
    errors = sorted(validator().iter_errors(out), key=lambda e: list(e.absolute_path))
    assert not errors, "\n".join(f"{list(e.absolute_path)}: {e.message}" for e in errors[:10])
    for key, by_channel in (out.get("resolved") or {}).items():
        assert set(out[key]) == set(out[f"{key}_ci95"]) == set(by_channel), key
        for ch, ok in by_channel.items():
            assert not ok or out[key][ch] is not None, (key, ch)  # resolved, never a null
    assert out["rig"] and "simulated" in out and out["verdict"]
