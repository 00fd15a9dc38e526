"""The effect catalogue (DESIGN.md section 8): injectable departures from the nominal model.

An effect is one module in this package that defines ``EFFECT``, an :class:`Effect`: its
name, its parameters with defaults and priors, and ``apply``, which returns a modified copy of
a :class:`~simhw.config.SimConfig`. ``catalogue()`` finds every module by scanning the
package, so adding an effect is adding a file, named for the effect; nothing else is edited
(``docs/procedures/writing.md``).

For the model-gap workflow an effect may also say which parameters the spectra identify
(``fit``; default all) and where to start looking (``guess``: given the workflow's evidence, an
object with ``peaks_hz`` (narrow excesses, strongest first), ``steps_urad`` (offset steps seen in
the time domain) and ``duration_s``, a list of parameter dicts; a value of a parameter not in
``fit`` holds it at that value, each such guess a candidate of its own), what the evidence says of
the held values' uncertainty (``spread``), and how its parameters read as applied (``derive``: e.g. a
bearing's eta follows from its stiffness and To).

The *nominal* model is the Ch. III plant with the gimbal-bearing torque omitted, as the
thesis began (Ch. V F); :func:`nominal` builds it.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from simhw.config import AXES, SimConfig


@dataclass(frozen=True)
class Param:
    """One effect parameter: default, prior range (for fitting and random draws) and unit."""

    name: str
    default: float
    lo: float
    hi: float
    log: bool = False  # draw/fit on a log scale
    doc: str = ""
    #: a bound of the prior that is a physical limit the data may reach ("lo" or "hi"); a fit
    #: at any other bound says the effect's form does not reach the data
    limit: str | None = None


@dataclass(frozen=True)
class Effect:
    name: str
    doc: str
    params: tuple[Param, ...]
    apply: Callable[..., SimConfig] = field(repr=False)
    key_param: str | None = None  # the parameter the gap workflow must recover
    fit: tuple[str, ...] | None = None  # parameters the spectra identify (None: all)
    guess: Callable[[Any], list[dict[str, float]]] | None = field(default=None, repr=False)
    derive: Callable[[dict[str, float]], dict[str, float]] | None = field(
        default=None, repr=False
    )  # params as applied
    #: 1-sigma of the parameters the spectra cannot see (held at a guess) as the evidence gives
    #: them: ``spread(evidence, params) -> {name: sigma}`` (a line's frequency from the time
    #: series, a jump's size from the steps' scatter)
    spread: Callable[[Any, dict[str, float]], dict[str, float]] | None = field(
        default=None, repr=False
    )
    #: parts of the model-gap analysis's nuisance (``procedures.analysis.gap.model``) that this
    #: effect describes itself: held while the effect is fitted or in the model
    owns: tuple[str, ...] = ()
    #: the effect may be present more than once (several mains harmonics are several pickup
    #: lines); each instance is applied on top of the others
    repeatable: bool = False

    @property
    def fit_params(self) -> tuple[Param, ...]:
        names = self.fit if self.fit is not None else tuple(p.name for p in self.params)
        return tuple(p for p in self.params if p.name in names)

    def inject(self, cfg: SimConfig, axis: str = "X", **values: float) -> SimConfig:
        """A copy of ``cfg`` with this effect on ``axis``; unknown or out-of-prior values raise."""
        if axis not in AXES:
            raise ValueError(
                f"effect {self.name}: unknown axis {axis!r} (one of {', '.join(AXES)})"
            )
        known = {p.name: p for p in self.params}
        for k, v in values.items():
            if k not in known:
                raise ValueError(
                    f"effect {self.name}: unknown parameter {k!r} "
                    f"(parameters: {', '.join(known) or 'none'})"
                )
            p = known[k]
            if not p.lo <= v <= p.hi:
                raise ValueError(f"effect {self.name}: {k} = {v} outside its range {p.lo}..{p.hi}")
        full = {p.name: p.default for p in self.params} | values
        return self.apply(cfg.copy(), axis, **full)


def catalogue() -> dict[str, Effect]:
    """Every effect module in this package, by name; a module named otherwise than its effect
    raises ``ValueError`` (``fbs gap`` names an effect, and a reader looks for its module)."""
    found: dict[str, Effect] = {}
    for info in pkgutil.iter_modules(__path__):
        module = importlib.import_module(f"{__name__}.{info.name}")
        effect = getattr(module, "EFFECT", None)
        if isinstance(effect, Effect):
            if effect.name != info.name:
                raise ValueError(
                    f"{module.__file__}: its effect is named {effect.name!r}: name the module "
                    f"for it ({effect.name}.py)"
                )
            found[effect.name] = effect
    return dict(sorted(found.items()))


def get(name: str) -> Effect:
    effects = catalogue()
    if name not in effects:
        raise ValueError(f"unknown effect {name!r} (known: {', '.join(effects)})")
    return effects[name]


def parse_spec(spec: str) -> tuple[Effect, dict[str, float], str]:
    """``name:k=v,k=v[,axis=Y]`` (the ``--effect`` option) -> (effect, values, axis)."""
    name, _, rest = spec.partition(":")
    effect = get(name.strip())
    values: dict[str, float] = {}
    axis = "X"
    for item in filter(None, (s.strip() for s in rest.split(","))):
        k, eq, v = item.partition("=")
        if not eq:
            raise ValueError(f"effect {effect.name}: expected key=value, got {item!r}")
        if k.strip() == "axis":
            axis = v.strip().upper()
            continue
        try:
            values[k.strip()] = float(v)
        except ValueError:
            raise ValueError(f"effect {effect.name}: {k.strip()} = {v!r} is not a number") from None
    return effect, values, axis


def primary_autocollimator(cfg: SimConfig, axis: str, effect: str):
    """The axis's primary-autocollimator parameters; only X and Y have one (Z is azimuth)."""
    if axis not in cfg.autocollimator:
        raise ValueError(f"effect {effect}: axis {axis} has no primary autocollimator (X or Y)")
    return cfg.autocollimator[axis]


def nominal(cfg: SimConfig | None = None) -> SimConfig:
    """The nominal model: the rig with the gimbal-bearing torque omitted (Ch. V F)."""
    cfg = (cfg or SimConfig()).copy()
    for b in cfg.bearing.values():
        b.model = "none"
    return cfg
