"""A step's result: a frozen dataclass, written as the JSON of one ``step-done`` event.

Every ``Step`` returns a ``StepResult`` subclass and names it (``Step.result``), so a resume
reads the recorded result back as the same type (``procedures.resume``). The JSON is the
fields by name; a float keeps ``digits`` significant digits (a class attribute: far finer than
the figure's standard error, and few enough that the result fits its event, ``TEXT_BYTES``;
the runner refuses one that does not, ``procedures.procedure.StepResultTooLarge``). Fields may
be ``bool``, ``int``, ``float``, ``str``, ``None``-able, tuples, lists, ``dict[str, ...]`` and
other step results, nested.

Common results (a wait, a recording) are here; a procedure's own are beside it, or in its
analysis module when the analysis reads them.
"""

from __future__ import annotations

import dataclasses
import math
import types
from collections.abc import Mapping
from typing import Any, ClassVar, Self, Union, get_args, get_origin, get_type_hints


class StepResultError(ValueError):
    """A recorded step result that does not read back as its type (another version's file)."""


@dataclasses.dataclass(frozen=True)
class StepResult:
    """Base of every step's result; subclasses are frozen dataclasses."""

    #: significant digits a float keeps in the event's JSON
    digits: ClassVar[int] = 10

    def to_json(self) -> dict[str, Any]:
        """The fields by name, floats to ``digits`` significant digits, tuples as lists."""
        return {f.name: _out(getattr(self, f.name), self.digits) for f in dataclasses.fields(self)}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Self:
        """The result ``to_json`` wrote (and ``json.loads`` read back)."""
        if not isinstance(data, Mapping):
            raise StepResultError(f"{cls.__name__}: a result is a JSON object, not {data!r}")
        hints = get_type_hints(cls)
        names = [f.name for f in dataclasses.fields(cls) if f.init]
        unknown = sorted(set(data) - set(names))
        if unknown:
            raise StepResultError(f"{cls.__name__}: unknown field(s) {', '.join(unknown)}")
        try:
            return cls(**{n: _in(hints[n], data[n]) for n in names if n in data})
        except (TypeError, ValueError) as exc:
            raise StepResultError(f"{cls.__name__}: {exc}") from None


@dataclasses.dataclass(frozen=True)
class Recorded(StepResult):
    """A data step that recorded ``seconds`` (where: the runner's span)."""

    seconds: float


@dataclasses.dataclass(frozen=True)
class Waited(StepResult):
    """A setup step that waited ``seconds`` (rig time) for transients to die away."""

    seconds: float


def round_sig(x: float, digits: int) -> float:
    """``x`` to ``digits`` significant digits (NaN and infinities as they are, and a number
    that rounding would carry past the largest float)."""
    x = float(x)
    y = float(f"{x:.{digits}g}") if math.isfinite(x) else x
    return y if math.isfinite(y) else x


def _out(v: Any, digits: int) -> Any:
    if isinstance(v, StepResult):
        return v.to_json()
    if isinstance(v, bool) or v is None or isinstance(v, str):
        return v
    if isinstance(v, int):
        return int(v)
    if isinstance(v, float):
        return round_sig(v, digits)
    if isinstance(v, tuple | list):
        return [_out(x, digits) for x in v]
    if isinstance(v, Mapping):
        return {str(k): _out(x, digits) for k, x in v.items()}
    # a numpy scalar: what a step computed with numpy
    if hasattr(v, "item"):
        return _out(v.item(), digits)
    raise TypeError(f"a step result cannot hold {type(v).__name__} ({v!r})")


def _in(tp: Any, v: Any) -> Any:
    """``v`` (plain JSON) as the type ``tp`` names."""
    origin, args = get_origin(tp), get_args(tp)
    if tp is Any:
        return v
    if origin in (Union, types.UnionType):
        if v is None and type(None) in args:
            return None
        errors = []
        for a in (a for a in args if a is not type(None)):
            try:
                return _in(a, v)
            except (TypeError, ValueError, StepResultError) as exc:
                errors.append(str(exc))
        raise ValueError(f"{v!r} is none of {tp}: {'; '.join(errors)}")
    if origin is tuple:
        items = list(_seq(v))
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_in(args[0], x) for x in items)
        if len(args) != len(items):
            raise ValueError(f"{v!r}: {len(items)} items, not {len(args)}")
        return tuple(_in(a, x) for a, x in zip(args, items, strict=True))
    if origin is list:
        return [_in(args[0], x) for x in _seq(v)]
    if origin is dict:
        if not isinstance(v, Mapping):
            raise ValueError(f"{v!r} is not an object")
        return {str(k): _in(args[1], x) for k, x in v.items()}
    if isinstance(tp, type) and issubclass(tp, StepResult):
        return tp.from_json(v)
    if tp is float:
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise ValueError(f"{v!r} is not a number")
        return float(v)
    if tp is int or tp is bool or tp is str:
        if type(v) is not tp:
            raise ValueError(f"{v!r} is not {tp.__name__}")
        return v
    if tp is type(None):
        if v is not None:
            raise ValueError(f"{v!r} is not null")
        return None
    raise TypeError(f"a step result cannot hold {tp}")


def _seq(v: Any) -> list[Any]:
    if not isinstance(v, list | tuple):
        raise ValueError(f"{v!r} is not a list")
    return list(v)
