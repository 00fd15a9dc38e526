"""Declared limits of a procedure's parameters: small validator objects, in the manner of
QCoDeS's standalone validators, attached to the ``Params`` dataclass's fields with
``typing.Annotated``::

    repetitions: Annotated[int, Range(1, 50)] = 3
    hold_s: Annotated[float, above(0)] = 20.0
    channels: Annotated[list[str], Each(OneOf(*GYRO_CHANNELS), nonempty=True)] = ...

A validator does two things from one declaration, so they cannot disagree:

* ``problem(value, name)``: "" when the value is within the limit, else the sentence that says
  why, naming the parameter, the value and the limit (``repetitions = 51 must be 1..50``);
  ``check`` raises it as ``ParamLimitError`` behind the procedure's name;
* ``describe()``: the limit alone, for help and forms (``1..50``, ``0.05..8 V``,
  ``one of X, Y, Z, XRD``).

``Annotated`` rather than ``dataclasses.field(metadata=...)``: the limit sits beside the type
it narrows and the default stays a plain default; mypy and ``typing.get_type_hints`` (without
``include_extras``, as ``procedures.paramtypes`` calls it) see the bare type, so the type rules
and ``procedures.params.parse_params`` are unchanged.

The annotations are strings (``from __future__ import annotations``), evaluated by
``typing.get_type_hints`` in the procedure module's namespace: a validator's arguments must be
names that module defines or imports (``GYRO_CHANNELS``), never a local.

Each ``Params.__post_init__`` calls ``check_limits(self, "name")`` before its own checks (a
dataclass runs no code of its own on construction), so a limit holds for ``Params(...)`` in
code as for ``--param``; what remains in ``__post_init__`` are the checks that tie several
parameters together (a band below the Nyquist frequency), which no one field can declare.

Types are not this module's business: ``procedures.paramtypes`` refuses ``1.5`` for an integer
before the dataclass sees it. A validator given a value of the wrong type says so rather than
raising a ``TypeError`` of its own.
"""

from __future__ import annotations

import abc
import dataclasses
import math
import numbers
import os
import stat
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any


class ParamLimitError(ValueError):
    """A parameter's value is outside its declared limit; the message names all three."""


class Validator(abc.ABC):
    """One limit on one parameter's value."""

    @abc.abstractmethod
    def problem(self, value: Any, name: str) -> str:
        """Why ``value`` breaks the limit, as ``<name> = <value> must be <limit>``; "" when it does not."""

    @abc.abstractmethod
    def describe(self) -> str:
        """The limit alone, as help shows it: ``1..50``, ``> 0``, ``one of X, Y``."""

    def check(self, value: Any, name: str, procedure: str) -> None:
        """Raise ``ParamLimitError`` ("``procedure``: why") when ``value`` is outside the limit."""
        why = self.problem(value, name)
        if why:
            raise ParamLimitError(f"{procedure}: {why}")


def _num(x: float) -> str:
    """A bound as written in a limit: shortest form that reads back exactly (8.0 -> 8, 1e3 -> 1000)."""
    if isinstance(x, numbers.Integral):
        return str(int(x))
    x = float(x)
    return str(int(x)) if x.is_integer() and abs(x) < 1e15 else repr(x)


def _shown(value: Any) -> str:
    """A value as a message shows it: numbers as written (51, 0.5), anything else by repr ('Z')."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return repr(value)
    return str(int(value)) if isinstance(value, numbers.Integral) else str(float(value))


def _with_note(text: str, note: str) -> str:
    return f"{text} ({note})" if note else text


@dataclass(frozen=True)
class Range(Validator):
    """A real number between ``lo`` and ``hi`` (either may be None: no bound on that side),
    each bound included unless ``lo_open``/``hi_open``; ``units`` (e.g. "V") follow the value
    and the limit in messages; ``note`` says why the limit is what it is, in messages only."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    units: str = ""
    note: str = ""

    def __post_init__(self) -> None:
        if self.lo is None and self.hi is None:
            raise ValueError("Range: give lo, hi or both (a limit with neither limits nothing)")
        if (
            self.lo is not None
            and self.hi is not None
            and not (
                self.lo < self.hi or (self.lo == self.hi and not (self.lo_open or self.hi_open))
            )
        ):
            raise ValueError(f"Range: {self.lo}..{self.hi} holds no value")

    def describe(self) -> str:
        u = f" {self.units}" if self.units else ""
        lo = None if self.lo is None else f"{'>' if self.lo_open else '>='} {_num(self.lo)}"
        hi = None if self.hi is None else f"{'<' if self.hi_open else '<='} {_num(self.hi)}"
        if self.lo is not None and self.hi is not None and not (self.lo_open or self.hi_open):
            return f"{_num(self.lo)}..{_num(self.hi)}{u}"
        return " and ".join(s for s in (lo, hi) if s) + u

    def contains(self, value: float) -> bool:
        """Whether the finite number ``value`` is within the bounds."""
        if self.lo is not None and not (value > self.lo if self.lo_open else value >= self.lo):
            return False
        return self.hi is None or (value < self.hi if self.hi_open else value <= self.hi)

    def problem(self, value: Any, name: str) -> str:
        limit = self.describe()
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            return _with_note(f"{name} = {_shown(value)} must be a number {limit}", self.note)
        shown = _shown(value) + (f" {self.units}" if self.units else "")
        if not math.isfinite(float(value)):
            return _with_note(f"{name} = {shown} must be finite and {limit}", self.note)
        if not self.contains(float(value)):
            return _with_note(f"{name} = {shown} must be {limit}", self.note)
        return ""


def above(lo: float, **kw: Any) -> Range:
    """``> lo`` (``above(0)``: a positive duration, rate, tolerance)."""
    return Range(lo, None, lo_open=True, **kw)


def at_least(lo: float, **kw: Any) -> Range:
    """``>= lo``."""
    return Range(lo, None, **kw)


@dataclass(frozen=True, init=False)
class OneOf(Validator):
    """One of a few fixed values (a channel, an axis)."""

    choices: tuple[Any, ...]
    note: str = ""

    def __init__(self, *choices: Any, note: str = "") -> None:
        if not choices:
            raise ValueError("OneOf: give at least one choice")
        object.__setattr__(self, "choices", choices)
        object.__setattr__(self, "note", note)

    def describe(self) -> str:
        return "one of " + ", ".join(str(c) for c in self.choices)

    def problem(self, value: Any, name: str) -> str:
        try:
            ok = value in self.choices
        except TypeError:  # an unhashable value compared with hashable choices
            ok = False
        return (
            ""
            if ok
            else _with_note(f"{name} = {_shown(value)} must be {self.describe()}", self.note)
        )


@dataclass(frozen=True)
class Each(Validator):
    """Every element of a list, or every value of a mapping, within ``item``; a mapping's keys
    within ``keys`` (if given); at least one element when ``nonempty``. An element is named
    ``name[i]`` in a list and ``name KEY`` in a mapping (``kto_urad_per_s_per_V X = 0``)."""

    item: Validator | None = None
    keys: Validator | None = None
    nonempty: bool = False

    def describe(self) -> str:
        parts = ["non-empty"] if self.nonempty else []
        if self.keys is not None:
            parts.append(f"keys {self.keys.describe()}")
        if self.item is not None:
            parts.append(f"{'values' if self.keys is not None else 'each'} {self.item.describe()}")
        return ", ".join(parts) if self.keys is None else "; ".join(parts)

    def problem(self, value: Any, name: str) -> str:
        if isinstance(value, Mapping):
            entries = [(f"{name} {k}", k, v) for k, v in value.items()]
        elif isinstance(value, (list, tuple)):
            entries = [(f"{name}[{i}]", None, v) for i, v in enumerate(value)]
        else:
            return f"{name} = {_shown(value)} must be a list or mapping, {self.describe()}"
        if self.nonempty and not entries:
            return f"{name} = {_shown(value)} must be {self.describe()}"
        for who, key, v in entries:
            if self.keys is not None and key is not None:
                why = self.keys.problem(key, f"{name} key")
                if why:
                    return why
            why = self.item.problem(v, who) if self.item is not None else ""
            if why:
                return why
        return ""


def _validators(hint: Any) -> tuple[Validator, ...]:
    """The validators an ``Annotated`` hint (or ``Annotated[...] | None``) carries."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return tuple(v for a in typing.get_args(hint) for v in _validators(a))
    if typing.get_origin(hint) is typing.Annotated:
        return tuple(m for m in hint.__metadata__ if isinstance(m, Validator))
    return ()


#: ``declared``'s answers: the annotations are strings, evaluated once per class
_DECLARED: dict[type, dict[str, tuple[Validator, ...]]] = {}


def declared(params_cls: type) -> dict[str, tuple[Validator, ...]]:
    """Each field of the dataclass ``params_cls`` that declares limits, and its validators (in
    field order)."""
    if params_cls not in _DECLARED:
        hints = typing.get_type_hints(params_cls, include_extras=True)
        found = {f.name: _validators(hints.get(f.name)) for f in dataclasses.fields(params_cls)}
        _DECLARED[params_cls] = {name: vs for name, vs in found.items() if vs}
    return _DECLARED[params_cls]


def check_limits(params: Any, procedure: str) -> None:
    """Raise ``ParamLimitError`` for the first field of the dataclass instance ``params`` whose
    value is outside a declared limit. ``None`` is never checked: it means "not given" (the
    procedure measures or looks the value up instead)."""
    for name, validators in declared(type(params)).items():
        value = getattr(params, name)
        if value is not None:
            for v in validators:
                v.check(value, name, procedure)


def describe_limits(params_cls: type) -> dict[str, str]:
    """Each limited field's limits as help shows them (``{"repetitions": "1..50"}``); the help of
    ``fbs run NAME --help`` and any parameter form read them from here."""
    return {
        name: " and ".join(v.describe() for v in vs) for name, vs in declared(params_cls).items()
    }


#: the sample rates a procedure may ask of the recorder: below 1 Hz no procedure has the samples
#: its settling and averaging need; above 20 kHz the ADC's aggregate rate (SIM-ADC16: 2 MHz over
#: up to 16 channels, docs/protocol.md) and the run file's disk budget are the limit, and every
#: procedure's band lies far below (its fastest line, 187 Hz, Ch. VI A)
MAX_PROCEDURE_RATE_HZ = 20_000.0


def sample_rate() -> Range:
    """The limit of every procedure's ``rate_hz``: 1..20000 Hz, declared so that a rate the
    ADC would refuse is refused before the rig or any output is opened."""
    return Range(
        1.0,
        MAX_PROCEDURE_RATE_HZ,
        units="Hz",
        note="the recorder's rates a procedure may use; the ADC's own limit is checked again",
    )


def fraction(**kw: Any) -> Range:
    """A fraction: ``0 < x <= 1`` (a tolerance of a nominal value, a share of samples)."""
    return Range(0.0, 1.0, lo_open=True, **kw)


@dataclass(frozen=True)
class ExistingFile(Validator):
    """The path of an existing regular file: a folder, a FIFO (a reader would wait forever on
    it) or a device is refused before anything reads it."""

    note: str = ""

    def describe(self) -> str:
        return "the path of an existing regular file"

    def problem(self, value: Any, name: str) -> str:
        if not isinstance(value, str) or not value:
            return _with_note(f"{name} = {_shown(value)} must be {self.describe()}", self.note)
        try:
            st = os.stat(value)
        except OSError as exc:
            return f"{name} = {value!r} must be {self.describe()} ({exc.strerror or exc})"
        if not stat.S_ISREG(st.st_mode):
            kind = (
                "a folder" if stat.S_ISDIR(st.st_mode) else "not a regular file (a FIFO or device?)"
            )
            return f"{name} = {value!r} must be {self.describe()}: it is {kind}"
        return ""
