"""Maximum-likelihood fits of catalogue effects to measured band spectra.

Each band estimate ``P_b`` of a channel is ``S_b chi^2_nu / nu`` under a model spectrum
``S_b``; its negative log-likelihood, up to terms free of the model, is the Whittle form
([Whittle 1953]; band-averaged, as in [BP] 9.4)

    -l = sum_b nu_b / 2 (ln S_b + P_b / S_b).

Channels are summed as independent; their correlation (the two autocollimator channels see
the same angle) makes the likelihood sharper than it is, which the ranking's margin absorbs.
The axis's autocollimator and pickoff noise levels are nuisance parameters, fitted for every
candidate (including ``none``) by profiling: the effect's own parameters are searched (prior
grid plus the effect's own guesses, then Nelder-Mead on the prior interval, log where the prior
is), and at every trial the two noise scales are re-fitted.

Candidates are ranked by the Bayesian information criterion's improvement over ``none``,
``2 (l_e - l_none) - k ln n`` ([Schwarz 1978]), ``k`` the effect's fitted parameters and ``n``
the number of band estimates.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from itertools import product
from typing import Any

import numpy as np
import scipy.optimize

from procedures.analysis.gap.model import PARTS, ModelSpectrum, SpectralModel
from simhw.effects import Effect, Param
from simhw.params import SimConfig

log = logging.getLogger(__name__)

#: Nuisance scales (of a part's power) are searched within this factor of the data sheet's
#: noise levels: the noise sources', and each pickoff line's (amplitude x 0.25 .. 4).
NUISANCE_RANGE = 4.0
LINE_RANGE = 16.0
#: The autocollimator's own 1/f level may differ from its white level's scaling by this factor
#: (its corner within 1-9 Hz; DESIGN.md section 3: "1/f below ~3 Hz"; an independent
#: unit-to-unit draw of 1/f level x0.6-1.4 rms, corner 2-4 Hz and white x0.6-1.4 rms puts 80 %
#: of corners within 1.1-7.6 Hz).
FLICKER_SHAPE_RANGE = 3.0


def whittle_nll(P: np.ndarray, S: np.ndarray, dof: np.ndarray) -> float:
    """sum nu/2 (ln S + P/S) over channels and bands (Whittle, band form)."""
    return float(np.sum(0.5 * dof * (np.log(S) + P / S)))


@dataclass
class NuisanceFit:
    scales: dict[str, float]
    nll: float
    S: np.ndarray


def fit_nuisance(P: np.ndarray, dof: np.ndarray, ms: ModelSpectrum, hold: frozenset[str] = frozenset(),
                 offsets: dict[str, float] | None = None) -> NuisanceFit:
    """Noise scales of the nuisance parts that minimize the Whittle likelihood (analytic gradient).

    Each part's power scale is free within its range, but the autocollimator's own 1/f
    ("ac_flicker") moves with its white ("ac") and differs from it only by a shape factor within
    ``FLICKER_SHAPE_RANGE`` (a corner from 1 to 9 Hz around the data sheet's 3 Hz); an excess
    1/f ("ac_excess") moves with the white and has no freedom of its own; a part in ``hold``
    (one an effect in the model describes itself) has none either, its shape factor staying at
    1 or at ``offsets[part]`` (a natural log: the ends of its range bound the systematic error
    of the effect that holds it, ``Fitter.held_envelope``).
    """
    active = [p for p in ms.parts if p != "fixed" and np.any(ms.parts[p] > 0)]
    fixed = ms.parts["fixed"]
    comps = [ms.parts[p] for p in active]
    tied = [p for p in ("ac_flicker", "ac_excess") if p in active]  # move with "ac"
    # log scale of each active part = M @ u + u0, u the free parameters within ``bounds``
    u0 = np.array([(offsets or {}).get(p, 0.0) if p in hold else 0.0 for p in active])
    columns: list[np.ndarray] = []
    bounds: list[tuple[float, float]] = []

    def free(rows: list[int], limit: float) -> None:
        col = np.zeros(len(active))
        col[rows] = 1.0
        columns.append(col)
        bounds.append((-math.log(limit), math.log(limit)))

    for i, p in enumerate(active):
        if p in ("ac_flicker", "ac_excess"):
            continue
        rows = [i] + ([active.index(t) for t in tied] if p == "ac" else [])
        if p not in hold:
            free(rows, LINE_RANGE if p not in PARTS else NUISANCE_RANGE)
    if "ac_flicker" in active and "ac_flicker" not in hold:
        free([active.index("ac_flicker")], FLICKER_SHAPE_RANGE if "ac" in active else NUISANCE_RANGE)
    M = np.array(columns).T if columns else np.zeros((len(active), 0))

    def f(u: np.ndarray) -> tuple[float, np.ndarray]:
        s = np.exp(M @ u + u0)
        S = fixed + sum(si * c for si, c in zip(s, comps))
        S = np.maximum(S, 1e-300)
        w = 0.5 * dof * (1.0 / S - P / S**2)
        grad = np.array([np.sum(w * c) * si for si, c in zip(s, comps)])
        return whittle_nll(P, S, dof), M.T @ grad

    u = np.zeros(M.shape[1])
    if M.shape[1]:
        u = scipy.optimize.minimize(f, u, jac=True, method="L-BFGS-B", bounds=bounds).x
    scales = dict(zip(active, np.exp(M @ u + u0).tolist()))
    S = ms.total(scales)
    return NuisanceFit(scales, whittle_nll(P, S, dof), S)


@dataclass
class EffectFit:
    """The best fit of one candidate effect on top of the base model."""

    effect: str
    params: dict[str, float]           # every parameter of the effect (fitted or held)
    errors: dict[str, float]           # 1-sigma of the fitted ones (``Fitter._errors``) and of held ones the data gave
    nll: float
    scales: dict[str, float]
    n_fitted: int
    cfg: SimConfig = field(repr=False)
    S: np.ndarray = field(repr=False)
    score: float = 0.0                 # BIC improvement over the base model
    #: 95 % intervals of the parameters with an error: (lo, hi), in the parameter's units
    intervals: dict[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def summary(self) -> dict[str, Any]:
        return {"effect": self.effect, "score": round(self.score, 2)}


def to_unit(p: Param, v: float) -> float:
    """A parameter's value in its search coordinate: 0..1 over its prior (log where the prior is)."""
    if p.log:
        return math.log(v / p.lo) / math.log(p.hi / p.lo)
    return (v - p.lo) / (p.hi - p.lo)


def _from_unit(p: Param, t: float) -> float:
    t = min(max(t, 0.0), 1.0)
    if p.log:
        return p.lo * (p.hi / p.lo) ** t
    return p.lo + t * (p.hi - p.lo)


#: The score contributions of this many adjacent bands form one cluster of the robust
#: ("sandwich") covariance: a model error is smooth across neighbouring 1/24-octave bands, so
#: their scores are not independent.
CLUSTER_BANDS = 4
Z95 = 1.959964


class Fitter:
    """Profile-likelihood fits of catalogue effects on one measured spectrum."""

    def __init__(self, model: SpectralModel, P: np.ndarray, dof: np.ndarray, axis: str,
                 grid_points: int = 9) -> None:
        self.model, self.P, self.dof, self.axis = model, P, np.broadcast_to(dof, P.shape), axis
        self.grid_points = grid_points
        self.evaluations = 0
        #: nuisance parts held because an effect already in the model describes them
        self.hold: frozenset[str] = frozenset()

    def base(self, cfg: SimConfig) -> NuisanceFit:
        return fit_nuisance(self.P, self.dof, self.model(cfg), self.hold)

    def fit(self, effect: Effect, base_cfg: SimConfig, evidence: Any, *, refine: bool = True,
            errors: bool = True, start: dict[str, float] | None = None,
            offsets: dict[str, float] | None = None) -> EffectFit | None:
        """The maximum-likelihood fit of ``effect`` on ``base_cfg``; None if it does not apply.
        Without ``refine``, the best of the starting points (a screening); without ``errors``,
        no curvature (NaN uncertainties). ``start``: begin from these values instead of the
        prior grid and the guesses (and hold what it gives of the parameters the spectra cannot
        see). A guess that gives such a parameter (a line's frequency measured in the time
        series, a jump's size) is a candidate of its own: each is fitted and the best kept.
        ``offsets``: the shape factors (natural log) of the nuisance parts the effect holds."""
        fitted = effect.fit_params
        defaults: dict[str, float] = {p.name: p.default for p in effect.params if p not in fitted}
        guesses = effect.guess(evidence) if effect.guess else []
        if effect.spread is not None and not guesses and start is None:
            # its held parameters come from the evidence (a line's frequency, the steps' size):
            # without evidence it is no candidate, not one at its defaults
            log.debug("%s: no evidence for its held parameters", effect.name)
            return None
        held_sets: list[dict[str, float]] = []
        for g in ([start] if start is not None else guesses):
            h = defaults | {k: v for k, v in g.items() if k in defaults}
            if h not in held_sets:
                held_sets.append(h)
        best: EffectFit | None = None
        for held in held_sets or [defaults]:
            f = self._fit_held(effect, base_cfg, evidence, held, guesses, refine=refine, errors=errors,
                               start=start, offsets=offsets)
            if f is not None and (best is None or f.nll < best.nll):
                best = f
        return best

    def _fit_held(self, effect: Effect, base_cfg: SimConfig, evidence: Any, held: dict[str, float],
                  guesses: list[dict[str, float]], *, refine: bool, errors: bool,
                  start: dict[str, float] | None, offsets: dict[str, float] | None) -> EffectFit | None:
        fitted = effect.fit_params
        try:
            effect.inject(base_cfg, self.axis, **{p.name: p.default for p in fitted}, **held)
        except ValueError as e:
            log.debug("%s does not apply: %s", effect.name, e)
            return None

        cache: dict[tuple, tuple[float, NuisanceFit, SimConfig]] = {}
        hold = self.hold | frozenset(effect.owns)

        def key_of(t: np.ndarray) -> tuple:
            return tuple(np.round(np.clip(t, 0, 1), 9))

        def evaluate(t: np.ndarray) -> float:
            key = key_of(t)
            if key not in cache:
                vals = {p.name: _from_unit(p, ti) for p, ti in zip(fitted, key)}
                cfg = effect.inject(base_cfg, self.axis, **vals, **held)
                nf = fit_nuisance(self.P, self.dof, self.model(cfg), hold, offsets)
                self.evaluations += 1
                cache[key] = (nf.nll, nf, cfg)
            return cache[key][0]

        def spectrum(t: np.ndarray) -> np.ndarray:
            evaluate(t)
            return cache[key_of(t)][1].S

        d = len(fitted)
        if d == 0:
            evaluate(np.zeros(0))
            best_t = np.zeros(0)
        else:
            n = self.grid_points if d == 1 else max(3, int(round(self.grid_points ** (1 / d) + 1)))
            axes = [np.linspace(0.5 / n, 1 - 0.5 / n, n)] * d
            starts = [np.array(s) for s in product(*axes)] if start is None else []
            for g in guesses if start is None else [start]:
                t = np.array([to_unit(p, g.get(p.name, p.default)) for p in fitted])
                starts.append(np.clip(t, 0.0, 1.0))
            scored = sorted(starts, key=evaluate)
            best_t, best_v = scored[0], evaluate(scored[0])
            # Refine the best start with a small simplex, as it already sits in its basin.
            for t0 in scored[:1] if refine else []:
                simplex = np.vstack([t0] + [t0 + 0.02 * np.eye(d)[i] for i in range(d)])
                res = scipy.optimize.minimize(evaluate, t0, method="Nelder-Mead", bounds=[(0.0, 1.0)] * d,
                                              options={"initial_simplex": np.clip(simplex, 0, 1), "xatol": 2e-4,
                                                       "fatol": 0.02, "maxfev": 40 * d})
                if res.fun < best_v:
                    best_t, best_v = np.clip(res.x, 0, 1), res.fun
        nll, nf, cfg = cache[key_of(best_t)]
        params = {p.name: _from_unit(p, t) for p, t in zip(fitted, best_t)} | held
        if effect.derive is not None:
            params = effect.derive(params)
        errs = {p.name: float("nan") for p in fitted}
        intervals: dict[str, tuple[float, float]] = {}
        if errors:
            errs, intervals = self._errors(evaluate, spectrum, best_t, fitted)
            if effect.spread is not None:  # what the data say of the held ones
                for k, sd in effect.spread(evidence, params).items():
                    if math.isfinite(sd) and sd > 0:
                        errs[k] = sd
                        intervals[k] = (params[k] - Z95 * sd, params[k] + Z95 * sd)
        return EffectFit(effect.name, params, errs, nll, nf.scales, d, cfg, nf.S, intervals=intervals)

    def held_envelope(self, effect: Effect, base_cfg: SimConfig, evidence: Any, found: EffectFit) -> EffectFit:
        """``found`` with its intervals widened by what the nuisance it holds leaves open.

        An effect that owns a nuisance part holds that part's shape at the data sheet's (the
        ``flicker_noise`` effect's excess 1/f and the unit's own 1/f have one shape and cannot
        be told apart): its estimate moves as that shape moves within its range. The interval
        is the union of the statistical intervals refitted with the held shape at each end of
        its range (a systematic error is bounded, not averaged)."""
        ranges = {p: FLICKER_SHAPE_RANGE for p in effect.owns if p == "ac_flicker"}
        if not ranges or not found.intervals:
            return found
        lo = dict((k, v[0]) for k, v in found.intervals.items())
        hi = dict((k, v[1]) for k, v in found.intervals.items())
        for sign in (-1.0, 1.0):
            alt = self.fit(effect, base_cfg, evidence, start=found.params,
                           offsets={p: sign * math.log(r) for p, r in ranges.items()})
            if alt is None:
                continue
            for k, (a, b) in alt.intervals.items():
                if k in lo:
                    lo[k], hi[k] = min(lo[k], a), max(hi[k], b)
        found.intervals = {k: (lo[k], hi[k]) for k in lo}
        return found

    def _errors(self, evaluate, spectrum, t: np.ndarray,
                fitted: tuple[Param, ...]) -> tuple[dict[str, float], dict[str, tuple[float, float]]]:
        """1-sigma and 95 % intervals of the fitted parameters, from a robust covariance.

        The model-based covariance is the inverse curvature H^-1 of -l (central differences in
        the unit coordinates). It holds only if the model is right and the bands independent; a
        model that is a little wrong everywhere (another unit's noise shapes) and channels that
        see the same angle make it too small. The robust ("sandwich") covariance
        H^-1 J H^-1 [Huber 1967; White 1982] takes J from the scores themselves, summed over the
        channels of each band and over ``CLUSTER_BANDS`` neighbouring bands (cluster-robust:
        what is correlated enters together); the larger of the two variances is used. Intervals
        are +-1.96 sigma in the unit coordinate, so a log-scaled parameter's is asymmetric, and
        end at its prior's bounds."""
        d = len(fitted)
        if d == 0:
            return {}, {}
        h = 2e-3
        f0 = evaluate(t)
        Hm = np.zeros((d, d))
        for i in range(d):
            for j in range(i, d):
                ei, ej = np.eye(d)[i] * h, np.eye(d)[j] * h
                if i == j:
                    v = (evaluate(t + ei) - 2 * f0 + evaluate(t - ei)) / h**2
                else:
                    v = (evaluate(t + ei + ej) - evaluate(t + ei - ej) - evaluate(t - ei + ej)
                         + evaluate(t - ei - ej)) / (4 * h * h)
                Hm[i, j] = Hm[j, i] = v
        nb = self.P.shape[1]
        G = np.zeros((nb, d))
        for i in range(d):
            tp, tm = np.clip(t + np.eye(d)[i] * h, 0, 1), np.clip(t - np.eye(d)[i] * h, 0, 1)
            Sp, Sm = spectrum(tp), spectrum(tm)
            lp = 0.5 * self.dof * (np.log(Sp) + self.P / Sp)
            lm = 0.5 * self.dof * (np.log(Sm) + self.P / Sm)
            G[:, i] = np.sum(lp - lm, axis=0) / max(tp[i] - tm[i], 1e-12)
        clusters = np.add.reduceat(G, np.arange(0, nb, CLUSTER_BANDS), axis=0)
        J = clusters.T @ clusters
        try:
            Hinv = np.linalg.inv(Hm)
            var = np.maximum(np.diag(Hinv), np.diag(Hinv @ J @ Hinv))
        except np.linalg.LinAlgError:
            var = np.full(d, np.nan)
        errs, intervals = {}, {}
        for i, p in enumerate(fitted):
            if not (np.isfinite(var[i]) and var[i] > 0):
                errs[p.name] = float("nan")
                continue
            v = _from_unit(p, t[i])
            sd_t = math.sqrt(var[i])
            # d value / d t: log scale -> v ln(hi/lo), linear -> hi - lo
            dv = v * math.log(p.hi / p.lo) if p.log else p.hi - p.lo
            errs[p.name] = float(abs(dv) * sd_t)
            intervals[p.name] = (_from_unit(p, t[i] - Z95 * sd_t), _from_unit(p, t[i] + Z95 * sd_t))
        return errs, intervals


def bic_score(fit: EffectFit, base_nll: float, n_obs: int) -> float:
    """BIC improvement over the base model: 2 (l_e - l_base) - k ln n."""
    return 2.0 * (base_nll - fit.nll) - fit.n_fitted * math.log(n_obs)
