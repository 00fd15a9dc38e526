"""Reported figures with their 95 % intervals and whether the data resolve them (DESIGN.md section 7).

Every figure key ``K`` of a procedure's JSON may carry ``K_ci95`` (same shape, ``[lo, hi]``) and
``resolved`` (``{K: {channel: bool}}``). A figure the data cannot resolve is reported as
``resolved: false`` with its interval, and its value is ``None``: never a bare number. The rule
(issue 18): a figure is unresolved when its 95 % interval is wider than its magnitude, or when
its estimate correlates with another of the same fit by more than ``MAX_CORRELATION`` (the
design cannot tell the two apart, so each is only known together with the other), or when the
interval is degenerate: zero width, or the value not strictly inside it (issue 38).

The procedures decide *how* an interval is made (generalised least squares, repeated
determinations, a block bootstrap, a profile); this module only carries it and applies the
rule, so every procedure reports alike.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.stats

#: beyond this |correlation| with another estimate of the same fit a figure is not resolved
MAX_CORRELATION = 0.95
LEVEL = 0.95


@dataclass(frozen=True)
class Estimate:
    """A figure, its 95 % interval and whether the data resolve it (``why`` says why not)."""

    value: float
    lo: float
    hi: float
    resolved: bool = True
    why: str = ""

    @property
    def half_width(self) -> float:
        return 0.5 * (self.hi - self.lo)

    def covers(self, truth: float) -> bool:
        return self.lo <= truth <= self.hi


def judged(
    value: float, lo: float, hi: float, *, correlation: float = 0.0, with_: str = ""
) -> Estimate:
    """An estimate with its interval, resolved unless the interval is degenerate (not finite, of
    zero width, or not holding the value strictly inside), wider than the value's magnitude, or
    ``|correlation|`` (with the estimate named ``with_``) exceeds ``MAX_CORRELATION``."""
    lo, hi = min(lo, hi), max(lo, hi)
    if not all(math.isfinite(v) for v in (value, lo, hi)):
        return Estimate(value, lo, hi, False, "no finite interval")
    # a degenerate interval is no measured error (issue 38 item 1: a fit pinned to the edge of
    # its search gave [v, v], "relative standard error 0 ... pass")
    if not hi > lo:
        return Estimate(
            value, lo, hi, False, "its 95 % interval has zero width: no error was measured"
        )
    if not lo < value < hi:
        where = "on" if value in (lo, hi) else "outside"
        return Estimate(
            value,
            lo,
            hi,
            False,
            f"the value lies {where} the edge of its 95 % interval [{lo:.4g}, {hi:.4g}]",
        )
    if abs(correlation) > MAX_CORRELATION:
        return Estimate(
            value, lo, hi, False, f"correlates {correlation:+.3f} with {with_ or 'another figure'}"
        )
    if hi - lo > abs(value):
        return Estimate(
            value, lo, hi, False, f"its 95 % interval ({hi - lo:.3g} wide) exceeds its magnitude"
        )
    return Estimate(value, lo, hi, True)


def from_stderr(
    value: float, se: float, *, dof: float | None = None, correlation: float = 0.0, with_: str = ""
) -> Estimate:
    """``value +- q se``, q the 97.5 % point of Student's t with ``dof`` degrees of freedom
    (the normal's without), then ``judged``."""
    q = (
        float(scipy.stats.t.ppf(0.5 + LEVEL / 2, dof))
        if dof
        else float(scipy.stats.norm.ppf(0.5 + LEVEL / 2))
    )
    return judged(value, value - q * se, value + q * se, correlation=correlation, with_=with_)


def through_scale(est: Estimate, rel_half_width: float) -> Estimate:
    """``est``, a figure read through a scale factor known to ``rel_half_width`` (95 %,
    relative: a pickoff's K_g from the stopwatch, or the data sheet's tolerance), its interval's
    half-width and the scale's share of the value combined in quadrature (GUM 5.1.6: the
    relative uncertainties of a quotient add in quadrature); an unresolved figure keeps its why.
    Without it a baseline's pickoff rms missed the truth 11 times in 80 (40 drawn rigs, two
    bands), a K_g 0.2-0.4 % off carrying it out of a +-0.1-0.3 % interval (issue 38)."""
    if not (math.isfinite(est.value) and rel_half_width > 0):
        return est
    # a figure that cannot be negative (an rms) stays so
    return widened(est, rel_half_width * abs(est.value), nonnegative=est.lo >= 0)


def widened(est: Estimate, allowance: float, *, nonnegative: bool = False) -> Estimate:
    """``est`` with a systematic ``allowance`` (95 %, absolute) added to its half-width in
    quadrature about the interval's middle (``nonnegative``: the low end kept >= 0); an
    unresolved figure keeps its why."""
    if not allowance > 0:
        return est
    mid, half = 0.5 * (est.lo + est.hi), math.hypot(est.half_width, allowance)
    lo, hi = mid - half, mid + half
    if nonnegative:
        lo = max(lo, 0.0)
    if not est.resolved:
        return Estimate(est.value, lo, hi, False, est.why)
    return judged(est.value, lo, hi)


def finite_json(obj: Any) -> Any:
    """``obj`` with every NaN or infinity None: strict JSON, where NaN is no number (a
    "± nan" read as a result)."""
    if isinstance(obj, float | np.floating):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: finite_json(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite_json(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return finite_json(obj.tolist())
    return obj


def finite_dumps(obj: Any, *, default: Callable[[Any], Any] | None = None, **kwargs: Any) -> str:
    """``json.dumps`` of ``obj`` as strict JSON (RFC 8259): every NaN or infinity null
    (``finite_json``), what ``default`` makes of an object too, never Python's ``NaN`` or
    ``Infinity`` tokens (jq, a browser and other languages' parsers refuse them)."""
    made = None if default is None else (lambda o: finite_json(default(o)))
    return json.dumps(finite_json(obj), default=made, allow_nan=False, **kwargs)


def add_figure(
    values: dict[str, Any], key: str, per_channel: Mapping[str, Estimate], digits: int = 6
) -> None:
    """Put figure ``key`` into a procedure's JSON ``values``: ``key`` ({channel: value, or None
    where unresolved}), ``key_ci95`` ({channel: [lo, hi]}) and ``resolved[key]``."""

    def r(v: float) -> float | None:
        return float(f"{v:.{digits}g}") if math.isfinite(v) else None

    values[key] = {ch: (r(e.value) if e.resolved else None) for ch, e in per_channel.items()}
    values[f"{key}_ci95"] = {ch: [r(e.lo), r(e.hi)] for ch, e in per_channel.items()}
    values.setdefault("resolved", {})[key] = {ch: e.resolved for ch, e in per_channel.items()}
